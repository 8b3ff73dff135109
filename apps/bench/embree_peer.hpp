#pragma once
// The CPU peer of the benchmark: Intel Embree 3 (what a CPU user would pick instead), over the same
// triangles, frames and rays as the toolkit's CPU runtime. Compiled only when Embree is found
// (TSAH_HAVE_EMBREE); embreeStatus() says why it is absent otherwise.
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "bench/ray_batch.hpp"

namespace tsah::bench {

// "3.13.5" when the bench was built with Embree, else a sentence saying it is missing.
std::string embreeStatus();
bool embreeAvailable();

#if TSAH_HAVE_EMBREE
class EmbreePeer {
 public:
  enum class Mode {
    RebuildMedium,  // a new BVH every frame, RTC_BUILD_QUALITY_MEDIUM (Embree's default, binned SAH)
    RebuildHigh,    // a new BVH every frame, RTC_BUILD_QUALITY_HIGH (spatial splits)
    Refit,          // RTC_BUILD_QUALITY_REFIT: built at the first update, refitted afterwards
  };
  static const char* modeName(Mode mode);  // embree-medium, embree-high, embree-refit

  // indices: 3 per triangle, each < vertexCount. threads: Embree's build threads (0: all cores).
  // Throws tsah::Failure when Embree cannot create its device or geometry.
  EmbreePeer(std::span<const uint32_t> indices, uint32_t vertexCount, Mode mode, unsigned threads);
  ~EmbreePeer();
  EmbreePeer(const EmbreePeer&) = delete;
  EmbreePeer& operator=(const EmbreePeer&) = delete;

  // Takes this frame's vertex positions (vertexCount * 3 floats): copies them into Embree's vertex
  // buffer and commits the scene (a rebuild or a refit, per mode). Returns the milliseconds spent.
  double update(std::span<const float> positions);

  // rtcIntersect1 / rtcOccluded1 on the committed scene.
  BatchTracer tracer() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};
#endif

}  // namespace tsah::bench
