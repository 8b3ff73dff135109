#pragma once
// The rays of one rendered frame, made once so that several ray tracers (the toolkit's CPU runtime,
// Embree) trace exactly the same rays: the renderer's three passes (tsah::renderFrame) with its
// camera rays and its per-pixel surface, ambient-occlusion and shadow rays (tsah/shading.hpp).
#include <cstdint>
#include <functional>
#include <vector>

#include "tsah/render/camera.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/render/renderer.hpp"

namespace tsah::bench {

struct RayBatch {
  std::vector<Ray> primary;  // one per pixel, row by row (closest hit)
  std::vector<Ray> ao;       // aoSamples per pixel that found a surface (any hit)
  std::vector<Ray> shadow;   // the shadow rays that are cast (any hit)
  uint64_t rays() const { return primary.size() + ao.size() + shadow.size(); }
};

// The rays renderFrame(runtime, camera, lighting, settings, ...) traces for the runtime's current
// frame: the primary rays are traced here with the runtime's tree to find the surfaces the
// secondary rays leave from. So the ray counts equal renderFrame's RenderStats.
RayBatch makeRayBatch(const CpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                      const RenderSettings& settings);

// What tracing a batch gave: time and count per pass (RenderStats' meaning), and the results, so
// that two tracers can be checked against each other.
struct BatchTrace {
  RayPassStats primary, ao, shadow;
  uint64_t primaryHits = 0, aoOccluded = 0, shadowOccluded = 0;
  RayPassStats total() const {
    return {primary.rays + ao.rays + shadow.rays, primary.ms + ao.ms + shadow.ms};
  }
};

// A ray tracer over chunks of a batch: closest(rays, first, count, hitCount) and
// occluded(rays, first, count, order, occludedCount) trace rays [first, first + count). `order` is
// the renderer's any-hit order of the pass (TreeOrder for the AO rays, FarthestFirst for the
// shadow rays); a tracer without that choice (Embree) ignores it.
struct BatchTracer {
  std::function<void(const std::vector<Ray>& rays, std::size_t first, std::size_t count, uint64_t& hits)> closest;
  std::function<void(const std::vector<Ray>& rays, std::size_t first, std::size_t count, AnyHitOrder order,
                     uint64_t& occluded)>
      occluded;
};

// Traces every pass of the batch with `tracer`, spread over the runtime's threads, each pass timed
// alone (wall clock).
BatchTrace traceBatch(const CpuRuntime& runtime, const RayBatch& batch, const BatchTracer& tracer);

// The toolkit's own tracer: CpuRuntime::closestHit / anyHit in the runtime's layout.
BatchTracer toolkitTracer(const CpuRuntime& runtime);

}  // namespace tsah::bench
