#pragma once
// Embree 3 set up as its user would for a scene file with instances (the two-level part of
// `tsah bench`, docs/bench.md): one RTCScene per static source, built once with
// RTC_BUILD_QUALITY_HIGH; one RTCScene per pose of an animated source (a distinct (source, time
// mapping): tsah::TwoLevelScene::poses, the sharing the toolkit's two-level runtime has), whose
// vertex buffer is filled from the source at the pose's local time and committed with
// RTC_BUILD_QUALITY_REFIT when that time changed; and a top-level RTCScene of instance geometries
// (RTC_SCENE_FLAG_DYNAMIC, RTC_BUILD_QUALITY_LOW, as Embree's dynamic-scene tutorial sets it), each
// given world(t) with rtcSetGeometryTransform, committed every frame. Compiled only with Embree.
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "bench/ray_batch.hpp"
#include "tsah/scene/two_level.hpp"

namespace tsah::bench {

#if TSAH_HAVE_EMBREE
class EmbreeInstancedPeer {
 public:
  // Runs body over [0, n) in chunks on the caller's worker threads (the poses' updates side by side).
  using ParallelFor = std::function<void(std::size_t n, const std::function<void(std::size_t, std::size_t)>& body)>;

  // Hits are reported as baked triangle ids (SceneSources::bakedTriangle of the instance and
  // Embree's primID). Keeps a reference to
  // `scene`. threads: Embree's worker threads (0: all cores). Throws tsah::Failure when Embree
  // reports an error.
  EmbreeInstancedPeer(const TwoLevelScene& scene, unsigned threads, ParallelFor parallelFor);
  ~EmbreeInstancedPeer();
  EmbreeInstancedPeer(const EmbreeInstancedPeer&) = delete;
  EmbreeInstancedPeer& operator=(const EmbreeInstancedPeer&) = delete;

  // Creates every source's and pose's scene at sceneTime and commits them and the top level.
  // Returns the milliseconds spent. Called once, before update.
  double build(double sceneTime);
  // The scene at sceneTime: each pose whose local time changed gets its vertices and a refit
  // commit, every instance its transform (an instance whose world matrix is singular is disabled
  // until it is invertible again, as the toolkit skips it), then the top level is committed.
  // Returns the milliseconds spent.
  double update(double sceneTime);
  uint32_t lastUpdateRefits() const;  // poses refitted by the last update
  uint32_t objectScenes() const;      // static sources + poses: the RTCScenes below the top level

  // rtcIntersect1 / rtcOccluded1 on the top level.
  BatchTracer tracer() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};
#endif

}  // namespace tsah::bench
