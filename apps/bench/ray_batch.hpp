#pragma once
// The rays of one rendered frame, made once so that several ray tracers (the toolkit's CPU runtime,
// Embree) trace exactly the same rays: the renderer's three passes (tsah::renderFrame) with its
// camera rays and its per-pixel surface, ambient-occlusion and shadow rays (tsah/shading.hpp).
#include <chrono>
#include <cstdint>
#include <functional>
#include <vector>

#include "tsah/render/camera.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/render/renderer.hpp"

namespace tsah::bench {

// Each ray's time in a motion-blurred frame, parallel to the rays of each pass (every ray of a
// pixel at the pixel's shutter fraction, pixelShutterTime); all empty for the instant.
struct RayTimes {
  std::vector<float> primary, ao, shadow;
  bool empty() const { return primary.empty(); }
};

struct RayBatch {
  std::vector<Ray> primary;  // one per pixel, row by row (closest hit)
  std::vector<Ray> ao;       // aoSamples per pixel that found a surface (any hit)
  std::vector<Ray> shadow;   // the shadow rays that are cast (any hit)
  RayTimes times;            // a blurred runtime's frame: the shutter fraction of every ray
  uint64_t rays() const { return primary.size() + ao.size() + shadow.size(); }
};

// The rays renderFrame(runtime, camera, lighting, settings, ...) traces for the runtime's current
// frame: the primary rays are traced here with the runtime's tree to find the surfaces the
// secondary rays leave from. So the ray counts equal renderFrame's RenderStats. A blurred runtime
// gives the rays of its blurred frame with their times (renderFrame's per-pixel times).
RayBatch makeRayBatch(const CpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                      const RenderSettings& settings);

// The same times in another tracer's convention (Embree's evenly spaced time steps), f applied to
// each shutter fraction.
RayTimes mapTimes(const RayTimes& times, const std::function<float(float)>& f);

// What tracing a batch gave: time and count per pass (RenderStats' meaning), and the results, so
// that two tracers can be checked against each other ray by ray.
struct BatchTrace {
  RayPassStats primary, ao, shadow;
  uint64_t primaryHits = 0, aoOccluded = 0, shadowOccluded = 0;
  std::vector<Hit> closest;                   // per primary ray: triangle (kNoHit: a miss) and t
  std::vector<uint8_t> aoResults, shadowResults;  // per AO / shadow ray: 1 when occluded
  RayPassStats total() const {
    return {primary.rays + ao.rays + shadow.rays, primary.ms + ao.ms + shadow.ms};
  }
};

// A ray tracer over chunks of a batch: closest(rays, times, count, hits) writes the closest hit of
// rays[0, count) into hits[0, count) (at times[i] when times is not null: a blurred frame; else
// the instant), occluded(rays, times, count, order, occluded) writes 1 for every occluded ray.
// `order` is the renderer's any-hit order of the pass (TreeOrder for the AO rays, FarthestFirst
// for the shadow rays); a tracer without that choice (Embree) ignores it.
struct BatchTracer {
  std::function<void(const Ray* rays, const float* times, std::size_t count, Hit* hits)> closest;
  std::function<void(const Ray* rays, const float* times, std::size_t count, AnyHitOrder order, uint8_t* occluded)>
      occluded;
};

// Rays per task of a pass of `rays` rays: at most 4096, and at least 128 tasks when the pass has
// 8192 rays or more, so that a small pass (a frame's shadow rays) also keeps every thread busy.
std::size_t raysPerTask(std::size_t rays);

// The threads a tracer's update and passes run on: a runtime's parallelFor(n, grain, body) (over
// [0, n) in chunks of at least grain) and how many threads it has.
struct Workers {
  std::function<void(std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body)>
      parallelFor;
  uint32_t threads = 1;
};
// A runtime's threads (CpuRuntime, TwoLevelRuntime: anything with parallelFor and threadCount).
template <class Runtime>
Workers workersOf(const Runtime& runtime) {
  return {[&runtime](std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body) {
            runtime.parallelFor(n, grain, body);
          },
          runtime.threadCount()};
}

// Wakes the workers and returns once every one of them has started a task, so that what is timed
// next starts on awake threads; false when some had not within `wait` (a busy machine). (A loop of
// empty tasks may end before sleeping workers join it, and they are then still waking during the
// timed work: an update after a frame's idle threads took about half as long again on the
// 16-core host.)
bool startWorkers(const Workers& workers, std::chrono::milliseconds wait = std::chrono::milliseconds(20));
bool startWorkers(const CpuRuntime& runtime);

// Traces every pass of the batch with `tracer`, spread over the workers' threads, each pass timed
// alone (wall clock). times: the batch's own (null) or the same times in the tracer's convention
// (mapTimes).
BatchTrace traceBatch(const Workers& workers, const RayBatch& batch, const BatchTracer& tracer,
                      const RayTimes* times = nullptr);
BatchTrace traceBatch(const CpuRuntime& runtime, const RayBatch& batch, const BatchTracer& tracer,
                      const RayTimes* times = nullptr);

// The toolkit's own tracer: CpuRuntime::closestHit / anyHit in the runtime's layout, at each ray's
// time when given.
BatchTracer toolkitTracer(const CpuRuntime& runtime);

}  // namespace tsah::bench
