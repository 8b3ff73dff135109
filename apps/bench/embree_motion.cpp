// Embree 3's motion-blur BVH (see embree_motion.hpp).
#include "bench/embree_motion.hpp"

#include <algorithm>

#include "tsah/layout/motion_blur.hpp"

#if TSAH_HAVE_EMBREE
#include <embree3/rtcore.h>

#include <chrono>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>

#include "bench/embree_device.hpp"
#include "tsah/base/error.hpp"
#endif

namespace tsah::bench {

float embreeStepTime(std::span<const float> keyFractions, float tau) {
  if (keyFractions.size() < 2) return 0.0f;
  const int count = int(keyFractions.size());
  const motion::Segment segment = motion::segmentAt(keyFractions.data(), count, tau);
  return std::min(1.0f, (float(segment.index) + segment.f) / float(count - 1));
}

#if TSAH_HAVE_EMBREE

struct EmbreeMotionPeer::Impl {
  std::unique_ptr<EmbreeDevice> device;
  RTCScene scene = nullptr;
  std::vector<uint32_t> indices;
  uint32_t vertexCount = 0, steps = 0;

  void check(const char* what) { device->check(what); }
};

EmbreeMotionPeer::EmbreeMotionPeer(std::span<const uint32_t> indices, uint32_t vertexCount, unsigned threads)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.indices.assign(indices.begin(), indices.end());
  m.vertexCount = vertexCount;
  m.device = std::make_unique<EmbreeDevice>(threads);
}

EmbreeMotionPeer::~EmbreeMotionPeer() {
  if (impl_->scene) rtcReleaseScene(impl_->scene);
}

uint32_t EmbreeMotionPeer::timeSteps() const { return impl_->steps; }

double EmbreeMotionPeer::build(std::span<const std::vector<float>> stepPositions) {
  Impl& m = *impl_;
  const std::size_t coordinates = std::size_t(m.vertexCount) * 3;
  if (stepPositions.empty()) throw tsah::DataError("Embree motion peer: no time steps");
  for (const std::vector<float>& p : stepPositions)
    if (p.size() != coordinates)
      throw tsah::DataError("Embree motion peer: expected " + std::to_string(coordinates) + " coordinates, got " +
                            std::to_string(p.size()));
  const auto start = std::chrono::steady_clock::now();
  // A new scene each time: the number of time steps may change from frame to frame.
  if (m.scene) rtcReleaseScene(m.scene);
  m.scene = rtcNewScene(m.device->get());
  rtcSetSceneBuildQuality(m.scene, RTC_BUILD_QUALITY_MEDIUM);
  // Embree takes at most RTC_MAX_TIME_STEP_COUNT time steps per geometry: longer motions become
  // geometries of consecutive steps sharing their boundary step, each present over its part of
  // Embree's time (rtcSetGeometryTimeRange, bounds computed as embreeStepTime computes ray times),
  // so one scene holds the whole motion and a ray at any time meets the triangles once or, at a
  // boundary, twice at the same place.
  const std::size_t n = stepPositions.size();
  const std::size_t perGeometry = RTC_MAX_TIME_STEP_COUNT - 1;  // time segments per geometry
  for (std::size_t first = 0; first == 0 || first + 1 < n; first += perGeometry) {
    const std::size_t last = std::min(first + perGeometry, n - 1);
    RTCGeometry geometry = rtcNewGeometry(m.device->get(), RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryTimeStepCount(geometry, unsigned(last - first + 1));
    if (n > RTC_MAX_TIME_STEP_COUNT)
      rtcSetGeometryTimeRange(geometry, float(first) / float(n - 1), float(last) / float(n - 1));
    for (std::size_t k = first; k <= last; ++k) {
      auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, unsigned(k - first),
                                                            RTC_FORMAT_FLOAT3, 3 * sizeof(float), m.vertexCount));
      if (!v) {
        rtcReleaseGeometry(geometry);
        m.check("allocating a vertex buffer");
        throw tsah::Failure("Embree: cannot allocate a vertex buffer");
      }
      std::memcpy(v, stepPositions[k].data(), coordinates * sizeof(float));
    }
    rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m.indices.data(), 0,
                               3 * sizeof(uint32_t), m.indices.size() / 3);
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(m.scene, geometry);
    rtcReleaseGeometry(geometry);  // the scene holds it
  }
  rtcCommitScene(m.scene);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  m.check("building the motion-blur scene");
  m.steps = uint32_t(stepPositions.size());
  return ms;
}

double EmbreeMotionPeer::build(const anim::Animation& animation, std::span<const double> keyTimes) {
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::vector<float>> steps;
  for (double t : keyTimes) steps.push_back(animation.positionsAt(t));
  const double interpolateMs =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return interpolateMs + build(steps);
}

uint32_t EmbreeMotionPeer::closestTriangle(const Ray& ray, float time) const {
  const Hit hit = embreeClosest(impl_->scene, ray, time);
  return hit.valid() ? hit.tri : kMiss;
}

bool EmbreeMotionPeer::occluded(const Ray& ray, float time) const { return embreeOccluded(impl_->scene, ray, time); }

BatchTracer EmbreeMotionPeer::tracer() const { return embreeTracer(impl_->scene, "Embree motion peer"); }

#endif

}  // namespace tsah::bench
