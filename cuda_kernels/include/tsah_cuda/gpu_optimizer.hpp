#pragma once
// The GPU parallel reinsertion optimizer: the rounds of tsah/reinsertion_rounds.hpp as CUDA kernels
// (search, claim, acceptance, apply, refit, cost sums on the device), the frame boxes of the
// interior nodes and the per-node round state in device memory. Same move, cost, round structure
// and stop rule as tsah::ParallelReinsertionOptimizer; the tree for a seed is the one
// tsah::optimizeEmulatedDevice computes on the host. See docs/optimizer.md.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "tsah/optimize/baselines.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"

namespace tsah::cuda {

// Throws CudaError (a tsah::Failure) when there is no usable device, tsah::DataError for bad input,
// tsah::ConfigError for more than 16 representative frames. prims must outlive the session.
std::unique_ptr<RoundSession> makeGpuReinsertionSession(Bvh bvh, const PrimitiveBoxes& prims,
                                                        const ParallelReinsertionOptimizer::Config& config,
                                                        const ParallelReinsertionOptimizer::Parallel& parallel);

// ParallelReinsertionOptimizer's loop over a GPU session (Parallel::threads is unused).
InsertionOptimizer::Result optimizeOnGpu(Bvh bvh, const PrimitiveBoxes& prims,
                                         const ParallelReinsertionOptimizer::Config& config,
                                         const ParallelReinsertionOptimizer::Parallel& parallel,
                                         const LeafCollapser* collapse = nullptr);

// How the search phase runs. The moves are the same either way; only the time differs.
struct GpuSearchKernel {
  bool specializedFrames = false;  // compiled for 1-5 and 8 frames: more registers, unrolled loops
  bool dynamicFetch = false;       // persistent threads taking the next candidate when done
};
// What optimizeOnGpu and makeGpuReinsertionSession run.
inline constexpr GpuSearchKernel kDefaultSearchKernel{};

struct GpuPhaseTime {
  std::string phase;     // the phase object's name (tsah/reinsertion_rounds.hpp), or a CUB step
  double seconds = 0.0;  // wall time of all its launches, each waited for
  uint64_t launches = 0;
};
// optimizeOnGpu (without collapse) with every phase waited for and timed, for finding where the
// time goes (slower than optimizeOnGpu). deviceBytes: the optimizer's buffers (CUB's included) at
// their peak. search: which search kernel runs.
InsertionOptimizer::Result profileOnGpu(Bvh bvh, const PrimitiveBoxes& prims,
                                        const ParallelReinsertionOptimizer::Config& config,
                                        const ParallelReinsertionOptimizer::Parallel& parallel,
                                        std::vector<GpuPhaseTime>& times, std::size_t& deviceBytes,
                                        GpuSearchKernel search = kDefaultSearchKernel);

// optimizeOnGpu with the default Parallel settings as a TreeOptions::gpuOptimizer (tsah/pipeline.hpp).
TreeOptimizerFunction gpuTreeOptimizer();

}  // namespace tsah::cuda
