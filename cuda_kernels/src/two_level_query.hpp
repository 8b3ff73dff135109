#pragma once
// The batch queries of the GPU two-level runtimes (instant: two_level_runtime.cpp; blurred:
// two_level_blur.cpp): one way to upload host rays, time the trace and bring its results back.
#include <cuda_runtime_api.h>

#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "event_timer.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda::detail {

// The trace's hits as two-level hits (instance kNoHit: none).
inline std::vector<TwoLevelHit> twoLevelHits(const std::vector<InstanceHit>& found) {
  std::vector<TwoLevelHit> out(found.size());
  for (std::size_t i = 0; i < found.size(); ++i) {
    if (found[i].instance == kNoHit) continue;
    out[i].t = found[i].t;
    out[i].u = found[i].u;
    out[i].v = found[i].v;
    out[i].instance = found[i].instance;
    out[i].prim = found[i].prim;
  }
  return out;
}

// A batch query's device buffers (grown, never shrunk). run uploads the rays, calls
// launch(rays, count, hits, occluded) between events 0 and 1 of `events` (hits null for any hits,
// occluded null for closest hits), and returns the results: TwoLevelHit per ray, or uint8_t (1:
// occluded).
struct TwoLevelQuery {
  DeviceBuffer<Ray> rays;
  DeviceBuffer<InstanceHit> hits;
  DeviceBuffer<uint8_t> occluded;

  template <bool AnyHit, typename Result, typename Launch>
  std::vector<Result> run(std::span<const Ray> in, EventTimer& events, cudaStream_t stream, RayPassStats* stats,
                          const Launch& launch) {
    std::vector<Result> out(in.size());
    if (stats) *stats = {};
    if (in.empty()) return out;
    if (in.size() > 0xffffffffu) throw ConfigError("GPU two-level runtime: too many rays in one call");
    const auto count = uint32_t(in.size());
    rays.reserve(count);
    rays.upload(in, stream);
    if (AnyHit)
      occluded.reserve(count);
    else
      hits.reserve(count);
    events.record(0, stream);
    launch(rays.data(), count, AnyHit ? nullptr : hits.data(), AnyHit ? occluded.data() : nullptr);
    events.record(1, stream);
    events.wait(1);
    if (stats) *stats = {count, events.ms(0, 1)};
    if constexpr (AnyHit) {
      const std::vector<uint8_t> found = occluded.download(stream, count);
      std::copy(found.begin(), found.end(), out.begin());
    } else {
      out = twoLevelHits(hits.download(stream, count));
    }
    return out;
  }
};

}  // namespace tsah::cuda::detail
