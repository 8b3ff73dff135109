// Embree 3 as the CPU peer (built only when CMake finds Embree).
#include "bench/embree_peer.hpp"

#include <embree3/rtcore.h>

#include <chrono>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>

#include "bench/embree_device.hpp"
#include "tsah/base/error.hpp"

namespace tsah::bench {

struct EmbreePeer::Impl {
  std::unique_ptr<EmbreeDevice> device;
  RTCScene scene = nullptr;
  RTCGeometry geometry = nullptr;
  float* vertices = nullptr;
  uint32_t vertexCount = 0;

  void check(const char* what) { device->check(what); }
};

EmbreeDevice::EmbreeDevice(unsigned threads) {
  const std::string config = threads > 0 ? "threads=" + std::to_string(threads) : std::string();
  device_ = rtcNewDevice(config.empty() ? nullptr : config.c_str());
  if (!device_) throw tsah::Failure("Embree: cannot create a device (rtcNewDevice)");
  rtcSetDeviceErrorFunction(
      device_,
      [](void* user, RTCError, const char* message) {
        auto* self = static_cast<EmbreeDevice*>(user);
        std::lock_guard<std::mutex> lock(self->mutex_);
        if (self->error_.empty() && message) self->error_ = message;
      },
      this);
}

EmbreeDevice::~EmbreeDevice() { rtcReleaseDevice(device_); }

void EmbreeDevice::check(const char* what) {
  if (rtcGetDeviceError(device_) == RTC_ERROR_NONE) return;
  std::lock_guard<std::mutex> lock(mutex_);
  throw tsah::Failure(std::string("Embree: ") + what + " failed" + (error_.empty() ? "" : ": " + error_));
}

const char* EmbreePeer::modeName(Mode mode) {
  switch (mode) {
    case Mode::RebuildMedium: return "embree-medium";
    case Mode::RebuildHigh: return "embree-high";
    case Mode::Refit: return "embree-refit";
  }
  return "embree";
}

EmbreePeer::EmbreePeer(std::span<const uint32_t> indices, uint32_t vertexCount, Mode mode, unsigned threads)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.vertexCount = vertexCount;
  m.device = std::make_unique<EmbreeDevice>(threads);
  m.scene = rtcNewScene(m.device->get());
  // Refit needs the two-level mode (scene quality LOW), the only one in which Embree honours a
  // per-geometry build quality; the rebuilds use one BVH over all triangles of the given quality.
  switch (mode) {
    case Mode::RebuildMedium: rtcSetSceneBuildQuality(m.scene, RTC_BUILD_QUALITY_MEDIUM); break;
    case Mode::RebuildHigh: rtcSetSceneBuildQuality(m.scene, RTC_BUILD_QUALITY_HIGH); break;
    case Mode::Refit:
      rtcSetSceneBuildQuality(m.scene, RTC_BUILD_QUALITY_LOW);
      rtcSetSceneFlags(m.scene, RTC_SCENE_FLAG_DYNAMIC);
      break;
  }
  m.geometry = rtcNewGeometry(m.device->get(), RTC_GEOMETRY_TYPE_TRIANGLE);
  if (mode == Mode::Refit) rtcSetGeometryBuildQuality(m.geometry, RTC_BUILD_QUALITY_REFIT);
  m.vertices = static_cast<float*>(rtcSetNewGeometryBuffer(m.geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                           3 * sizeof(float), vertexCount));
  auto* tris = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(m.geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                              3 * sizeof(uint32_t), indices.size() / 3));
  m.check("creating the triangle geometry");
  if (!m.vertices || !tris) throw tsah::Failure("Embree: cannot allocate the geometry buffers");
  std::memcpy(tris, indices.data(), indices.size_bytes());
  std::memset(m.vertices, 0, std::size_t(vertexCount) * 3 * sizeof(float));
  rtcCommitGeometry(m.geometry);
  rtcAttachGeometry(m.scene, m.geometry);
  m.check("attaching the geometry");
}

EmbreePeer::~EmbreePeer() {
  if (impl_->geometry) rtcReleaseGeometry(impl_->geometry);
  if (impl_->scene) rtcReleaseScene(impl_->scene);
}

double EmbreePeer::update(std::span<const float> positions) {
  Impl& m = *impl_;
  if (positions.size() != std::size_t(m.vertexCount) * 3)
    throw tsah::DataError("Embree peer: expected " + std::to_string(std::size_t(m.vertexCount) * 3) +
                          " coordinates, got " + std::to_string(positions.size()));
  const auto start = std::chrono::steady_clock::now();
  std::memcpy(m.vertices, positions.data(), positions.size_bytes());
  rtcUpdateGeometryBuffer(m.geometry, RTC_BUFFER_TYPE_VERTEX, 0);
  rtcCommitGeometry(m.geometry);
  rtcCommitScene(m.scene);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  m.check("committing the scene");
  return ms;
}

RTCRay embreeRay(const Ray& r, float time) {
  RTCRay ray;
  ray.org_x = r.org.x;
  ray.org_y = r.org.y;
  ray.org_z = r.org.z;
  ray.tnear = r.tmin;
  ray.dir_x = r.dir.x;
  ray.dir_y = r.dir.y;
  ray.dir_z = r.dir.z;
  ray.time = time;
  ray.tfar = r.tmax;
  ray.mask = 0xffffffffu;
  ray.id = 0;
  ray.flags = 0;
  return ray;
}

Hit embreeClosest(RTCScene scene, const Ray& ray, float time) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray = embreeRay(ray, time);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene, &context, &rh);
  Hit hit;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
  hit.tri = rh.hit.primID;
  hit.t = rh.ray.tfar;
  hit.u = rh.hit.u;
  hit.v = rh.hit.v;
  return hit;
}

bool embreeOccluded(RTCScene scene, const Ray& ray, float time) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay r = embreeRay(ray, time);
  rtcOccluded1(scene, &context, &r);
  return r.tfar < 0.0f;  // Embree sets tfar to -inf for an occluded ray
}

BatchTracer EmbreePeer::tracer() const {
  const RTCScene scene = impl_->scene;
  BatchTracer tracer;
  // One time step: the rays' times (a blurred batch's) do not move anything.
  tracer.closest = [scene](const Ray* rays, const float*, std::size_t count, Hit* hits) {
    for (std::size_t i = 0; i < count; ++i) hits[i] = embreeClosest(scene, rays[i], 0.0f);
  };
  // Embree has no choice of order for occlusion rays (it never sorts them): the order is ignored.
  tracer.occluded = [scene](const Ray* rays, const float*, std::size_t count, AnyHitOrder, uint8_t* occluded) {
    for (std::size_t i = 0; i < count; ++i) occluded[i] = embreeOccluded(scene, rays[i], 0.0f) ? 1 : 0;
  };
  return tracer;
}

}  // namespace tsah::bench
