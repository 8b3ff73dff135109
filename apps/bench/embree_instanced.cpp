// Embree 3 instancing as the peer of the two-level runtime (see embree_instanced.hpp).
#include "bench/embree_instanced.hpp"

#if TSAH_HAVE_EMBREE
#include <embree3/rtcore.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <span>

#include "bench/embree_device.hpp"
#include "tsah/base/error.hpp"
#include "tsah/scene/two_level_runtime.hpp"

namespace tsah::bench {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

struct EmbreeInstancedPeer::Impl {
  // One RTCScene below the top level: a static source's, or a pose's.
  struct Object {
    const anim::Animation* source = nullptr;
    bool animated = false;
    anim::TimeMapping time;  // a pose's time mapping
    RTCScene scene = nullptr;
    RTCGeometry geometry = nullptr;
    float* vertices = nullptr;
    double localTime = std::numeric_limits<double>::quiet_NaN();  // of the last vertex update
  };
  const TwoLevelScene& scene;
  ParallelFor parallelFor;
  std::unique_ptr<EmbreeDevice> device;
  std::vector<Object> objects;
  std::vector<uint32_t> instanceObject;  // per instance: its object
  std::vector<RTCGeometry> instances;
  std::vector<uint8_t> enabled;
  RTCScene top = nullptr;
  uint32_t lastRefits = 0;

  Impl(const TwoLevelScene& s, ParallelFor p) : scene(s), parallelFor(std::move(p)) {}
  ~Impl() {
    for (RTCGeometry g : instances) rtcReleaseGeometry(g);
    for (Object& o : objects) {
      if (o.geometry) rtcReleaseGeometry(o.geometry);
      if (o.scene) rtcReleaseScene(o.scene);
    }
    if (top) rtcReleaseScene(top);
  }

  double localTimeOf(const Object& o, double sceneTime) const {
    return o.time.localTime(sceneTime, o.source->startTime(), o.source->endTime());
  }

  void makeObject(Object& o, double sceneTime) {
    const anim::Animation& a = *o.source;
    o.scene = rtcNewScene(device->get());
    if (o.animated) {
      // Embree honours a geometry's REFIT quality only in its two-level mode (scene quality LOW).
      rtcSetSceneBuildQuality(o.scene, RTC_BUILD_QUALITY_LOW);
      rtcSetSceneFlags(o.scene, RTC_SCENE_FLAG_DYNAMIC);
    } else {
      rtcSetSceneBuildQuality(o.scene, RTC_BUILD_QUALITY_HIGH);  // built once: the best tree
    }
    o.geometry = rtcNewGeometry(device->get(), RTC_GEOMETRY_TYPE_TRIANGLE);
    if (o.animated) rtcSetGeometryBuildQuality(o.geometry, RTC_BUILD_QUALITY_REFIT);
    o.vertices = static_cast<float*>(rtcSetNewGeometryBuffer(o.geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                             3 * sizeof(float), a.vertexCount()));
    auto* tris = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(o.geometry, RTC_BUFFER_TYPE_INDEX, 0,
                                                                RTC_FORMAT_UINT3, 3 * sizeof(uint32_t),
                                                                a.triangleCount()));
    device->check("creating a source's triangle geometry");
    if (!o.vertices || !tris) throw tsah::Failure("Embree: cannot allocate the geometry buffers");
    std::copy(a.indices().begin(), a.indices().end(), tris);
    o.localTime = o.animated ? localTimeOf(o, sceneTime) : a.startTime();
    a.positionsAt(o.localTime, std::span<float>(o.vertices, std::size_t(a.vertexCount()) * 3));
    rtcCommitGeometry(o.geometry);
    rtcAttachGeometry(o.scene, o.geometry);
    rtcCommitScene(o.scene);
    device->check("committing a source's scene");
  }

  // Each instance's world(t) (row-major 3x4, the first three rows of anim::Matrix4); a singular one
  // disables the instance until it is invertible again.
  void placeInstances(double sceneTime) {
    for (std::size_t i = 0; i < instances.size(); ++i) {
      const anim::Matrix4 world = scene.scene.instances[i].worldAt(sceneTime);
      const bool invertible = instanceSpace(world).has_value();
      if (invertible) {
        float rows[12];
        for (int k = 0; k < 12; ++k) rows[k] = float(world[std::size_t(k)]);
        rtcSetGeometryTransform(instances[i], 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, rows);
        rtcCommitGeometry(instances[i]);
      }
      if (invertible != bool(enabled[i])) {
        if (invertible)
          rtcEnableGeometry(instances[i]);
        else
          rtcDisableGeometry(instances[i]);
        enabled[i] = invertible ? 1 : 0;
      }
    }
    rtcCommitScene(top);
  }
};

EmbreeInstancedPeer::EmbreeInstancedPeer(const TwoLevelScene& scene, unsigned threads, ParallelFor parallelFor)
    : impl_(std::make_unique<Impl>(scene, std::move(parallelFor))) {
  impl_->device = std::make_unique<EmbreeDevice>(threads);
}

EmbreeInstancedPeer::~EmbreeInstancedPeer() = default;

double EmbreeInstancedPeer::build(double sceneTime) {
  Impl& m = *impl_;
  const TwoLevelScene& s = m.scene;
  const auto start = std::chrono::steady_clock::now();
  // Objects: every static source, then every pose (the toolkit's pose sharing).
  std::vector<uint32_t> staticObject(s.blases.size(), kInvalidIndex);
  for (std::size_t b = 0; b < s.blases.size(); ++b) {
    if (s.blases[b].animated) continue;
    staticObject[b] = uint32_t(m.objects.size());
    m.objects.push_back({s.scene.sources[s.blases[b].source].get(), false, {}, nullptr, nullptr, nullptr, 0.0});
  }
  const uint32_t firstPose = uint32_t(m.objects.size());
  for (const Pose& p : s.poses)
    m.objects.push_back({s.scene.sources[s.blases[p.blas].source].get(), true, p.time, nullptr, nullptr, nullptr, 0.0});
  for (Impl::Object& o : m.objects) m.makeObject(o, sceneTime);

  m.top = rtcNewScene(m.device->get());
  rtcSetSceneFlags(m.top, RTC_SCENE_FLAG_DYNAMIC);
  rtcSetSceneBuildQuality(m.top, RTC_BUILD_QUALITY_LOW);
  for (uint32_t i = 0; i < s.instanceCount(); ++i) {
    const uint32_t pose = s.instancePose[i];
    const uint32_t object = pose == kInvalidIndex ? staticObject[s.scene.instances[i].source] : firstPose + pose;
    m.instanceObject.push_back(object);
    RTCGeometry g = rtcNewGeometry(m.device->get(), RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(g, m.objects[object].scene);
    rtcSetGeometryTimeStepCount(g, 1);
    rtcAttachGeometryByID(m.top, g, i);  // instID of a hit = the instance
    m.instances.push_back(g);
    m.enabled.push_back(1);
  }
  m.device->check("creating the instances");
  m.placeInstances(sceneTime);
  const double ms = msSince(start);
  m.device->check("committing the top level");
  return ms;
}

double EmbreeInstancedPeer::update(double sceneTime) {
  Impl& m = *impl_;
  const auto start = std::chrono::steady_clock::now();
  std::vector<uint8_t> refitted(m.objects.size(), 0);
  m.parallelFor(m.objects.size(), [&](std::size_t first, std::size_t last) {
    for (std::size_t k = first; k < last; ++k) {
      Impl::Object& o = m.objects[k];
      if (!o.animated) continue;
      const double local = m.localTimeOf(o, sceneTime);
      if (local == o.localTime) continue;  // a held pose keeps its tree, as the toolkit's
      o.localTime = local;
      o.source->movingPositionsAt(local, std::span<float>(o.vertices, std::size_t(o.source->vertexCount()) * 3));
      rtcUpdateGeometryBuffer(o.geometry, RTC_BUFFER_TYPE_VERTEX, 0);
      rtcCommitGeometry(o.geometry);
      rtcCommitScene(o.scene);  // a refit (RTC_BUILD_QUALITY_REFIT)
      refitted[k] = 1;
    }
  });
  m.lastRefits = 0;
  for (uint8_t r : refitted) m.lastRefits += r;
  m.placeInstances(sceneTime);
  const double ms = msSince(start);
  m.device->check("updating the instanced scene");
  return ms;
}

uint32_t EmbreeInstancedPeer::lastUpdateRefits() const { return impl_->lastRefits; }

uint32_t EmbreeInstancedPeer::objectScenes() const { return uint32_t(impl_->objects.size()); }

BatchTracer EmbreeInstancedPeer::tracer() const {
  const RTCScene top = impl_->top;
  const anim::SceneSources* sources = &impl_->scene.scene;
  BatchTracer tracer;
  tracer.closest = [top, sources](const Ray* rays, const float*, std::size_t count, Hit* hits) {
    for (std::size_t i = 0; i < count; ++i) {
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      RTCRayHit rh;
      rh.ray = embreeRay(rays[i], 0.0f);
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(top, &context, &rh);
      Hit hit;
      if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
        hit.tri = sources->bakedTriangle(rh.hit.instID[0], rh.hit.primID);
        hit.t = rh.ray.tfar;
        hit.u = rh.hit.u;
        hit.v = rh.hit.v;
      }
      hits[i] = hit;
    }
  };
  // Embree has no choice of order for occlusion rays: the order is ignored.
  tracer.occluded = [top](const Ray* rays, const float*, std::size_t count, AnyHitOrder, uint8_t* occluded) {
    for (std::size_t i = 0; i < count; ++i) occluded[i] = embreeOccluded(top, rays[i], 0.0f) ? 1 : 0;
  };
  return tracer;
}

}  // namespace tsah::bench
#endif
