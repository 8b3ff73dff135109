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

// Embree takes at most RTC_MAX_TIME_STEP_COUNT time steps per geometry, and in Embree 3.13 a
// geometry's time range (rtcSetGeometryTimeRange) does not hide it outside the range: a ray meets
// it there at its first or last step. So a longer motion becomes pieces of consecutive steps,
// sharing their boundary step, each its own scene over its part [start, end] of Embree's time (the
// bounds computed as embreeStepTime computes ray times); a ray traces the piece of its time.
struct EmbreeMotionPeer::Impl {
  struct Piece {
    RTCScene scene = nullptr;
    float start = 0.0f, end = 1.0f;
  };
  std::unique_ptr<EmbreeDevice> device;
  std::vector<Piece> pieces;
  std::vector<uint32_t> indices;
  uint32_t vertexCount = 0, steps = 0;

  void check(const char* what) { device->check(what); }
  void release() {
    for (Piece& p : pieces) rtcReleaseScene(p.scene);
    pieces.clear();
  }
  // The piece of Embree time `time` and the time inside it.
  std::pair<RTCScene, float> at(float time) const {
    std::size_t p = 0;
    while (p + 1 < pieces.size() && time > pieces[p].end) ++p;
    const Piece& piece = pieces[p];
    if (pieces.size() == 1) return {piece.scene, time};
    return {piece.scene, std::clamp((time - piece.start) / (piece.end - piece.start), 0.0f, 1.0f)};
  }
};

EmbreeMotionPeer::EmbreeMotionPeer(std::span<const uint32_t> indices, uint32_t vertexCount, unsigned threads)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.indices.assign(indices.begin(), indices.end());
  m.vertexCount = vertexCount;
  m.device = std::make_unique<EmbreeDevice>(threads);
}

EmbreeMotionPeer::~EmbreeMotionPeer() { impl_->release(); }

uint32_t EmbreeMotionPeer::timeSteps() const { return impl_->steps; }

uint32_t EmbreeMotionPeer::pieces() const { return uint32_t(impl_->pieces.size()); }

double EmbreeMotionPeer::build(std::span<const std::vector<float>> stepPositions) {
  Impl& m = *impl_;
  const std::size_t coordinates = std::size_t(m.vertexCount) * 3;
  if (stepPositions.empty()) throw tsah::DataError("Embree motion peer: no time steps");
  for (const std::vector<float>& p : stepPositions)
    if (p.size() != coordinates)
      throw tsah::DataError("Embree motion peer: expected " + std::to_string(coordinates) + " coordinates, got " +
                            std::to_string(p.size()));
  const auto start = std::chrono::steady_clock::now();
  // New scenes each time: the number of time steps may change from frame to frame.
  m.release();
  m.steps = 0;
  const std::size_t n = stepPositions.size();
  const std::size_t perPiece = RTC_MAX_TIME_STEP_COUNT - 1;  // time segments per piece
  for (std::size_t first = 0; first == 0 || first + 1 < n; first += perPiece) {
    const std::size_t last = std::min(first + perPiece, n - 1);
    Impl::Piece piece;
    piece.scene = rtcNewScene(m.device->get());
    if (n > 1) {
      piece.start = float(first) / float(n - 1);
      piece.end = float(last) / float(n - 1);
    }
    m.pieces.push_back(piece);
    rtcSetSceneBuildQuality(piece.scene, RTC_BUILD_QUALITY_MEDIUM);
    RTCGeometry geometry = rtcNewGeometry(m.device->get(), RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryTimeStepCount(geometry, unsigned(last - first + 1));
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
    rtcAttachGeometry(piece.scene, geometry);
    rtcReleaseGeometry(geometry);  // the scene holds it
    rtcCommitScene(piece.scene);
  }
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  m.check("building the motion-blur scene");
  m.steps = uint32_t(n);
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
  const auto [scene, local] = impl_->at(time);
  const Hit hit = embreeClosest(scene, ray, local);
  return hit.valid() ? hit.tri : kMiss;
}

bool EmbreeMotionPeer::occluded(const Ray& ray, float time) const {
  const auto [scene, local] = impl_->at(time);
  return embreeOccluded(scene, ray, local);
}

BatchTracer EmbreeMotionPeer::tracer() const {
  const Impl* m = impl_.get();
  const auto check = [](const float* times) {
    if (!times) throw tsah::ConfigError("Embree motion peer: the rays carry no times");
  };
  BatchTracer tracer;
  tracer.closest = [m, check](const Ray* rays, const float* times, std::size_t count, Hit* hits) {
    check(times);
    for (std::size_t i = 0; i < count; ++i) {
      const auto [scene, local] = m->at(times[i]);
      hits[i] = embreeClosest(scene, rays[i], local);
    }
  };
  tracer.occluded = [m, check](const Ray* rays, const float* times, std::size_t count, AnyHitOrder,
                               uint8_t* occluded) {
    check(times);
    for (std::size_t i = 0; i < count; ++i) {
      const auto [scene, local] = m->at(times[i]);
      occluded[i] = embreeOccluded(scene, rays[i], local) ? 1 : 0;
    }
  };
  return tracer;
}

#endif

}  // namespace tsah::bench
