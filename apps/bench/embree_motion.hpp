#pragma once
// Embree 3's motion-blur BVH, the peer of the toolkit's blurred frames: triangles with a vertex
// buffer per time step, a ray's time in Embree's [0, 1]. Built over the whole animation once (its
// keyframes as the time steps) or per frame over the shutter's keys (a rebuild every frame).
// Compiled only with Embree (TSAH_HAVE_EMBREE), beside embree_peer.cpp.
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "anim/animation.hpp"
#include "bench/ray_batch.hpp"
#include "tsah/core/ray.hpp"

namespace tsah::bench {

// Embree spaces the time steps evenly over [0, 1]; the keys need not be. A ray's time tau (a
// fraction of the keys' span) lies at f in segment s of keyFractions (motion::segmentAt: first 0,
// last 1, increasing, as motion::keyFractions gives them); between two consecutive keys the
// animation and Embree both move every vertex linearly, so Embree's time (s + f) / (K - 1) gives the
// same positions. One key gives 0.
float embreeStepTime(std::span<const float> keyFractions, float tau);

#if TSAH_HAVE_EMBREE
class EmbreeMotionPeer {
 public:
  static constexpr uint32_t kMiss = 0xffffffffu;

  // indices: 3 per triangle, each < vertexCount. threads: Embree's build threads (0: all cores).
  // Throws tsah::Failure when Embree cannot create its device.
  EmbreeMotionPeer(std::span<const uint32_t> indices, uint32_t vertexCount, unsigned threads);
  ~EmbreeMotionPeer();
  EmbreeMotionPeer(const EmbreeMotionPeer&) = delete;
  EmbreeMotionPeer& operator=(const EmbreeMotionPeer&) = delete;

  // Builds a new motion-blur BVH (RTC_BUILD_QUALITY_MEDIUM) with one time step per entry of
  // stepPositions (vertexCount * 3 floats each, at least one; beyond Embree's 129 steps per
  // geometry, one BVH per piece of 128 time segments, each ray traced in the piece of its time);
  // returns the milliseconds spent, copies included. Throws tsah::DataError for a wrong
  // coordinate count.
  double build(std::span<const std::vector<float>> stepPositions);
  // The same with the animation's vertices at each of keyTimes (increasing: its keyframe times for
  // the whole animation, motion::shutterKeys for one frame's shutter); the interpolation counts in
  // the milliseconds, as it does in the toolkit's update.
  double build(const anim::Animation& animation, std::span<const double> keyTimes);
  uint32_t timeSteps() const;
  uint32_t pieces() const;  // BVHs the time steps are spread over (1 up to 129 steps)

  // rtcIntersect1 / rtcOccluded1 at Embree time `time` (embreeStepTime): the triangle hit first
  // (kMiss for none), or whether anything lies on the ray.
  uint32_t closestTriangle(const Ray& ray, float time) const;
  bool occluded(const Ray& ray, float time) const;
  // The same for a batch, each ray at its time in Embree's convention (mapTimes with
  // embreeStepTime); a batch without times is a ConfigError.
  BatchTracer tracer() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};
#endif

}  // namespace tsah::bench
