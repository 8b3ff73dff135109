#pragma once
// The GPU optimizer's rounds (reinsertion_rounds.hpp) run serially on the host: every phase a loop
// over its thread indices, phases one after another as the kernels are launched. It gives the GPU
// optimizer's tree (bit for bit, for a seed) on a machine without a GPU, so that tests check the
// device algorithm everywhere; it is far slower than both real optimizers.
#include <cstddef>
#include <memory>

#include "tsah/optimize/parallel_optimizer.hpp"

namespace tsah {

// Throws tsah::DataError for bad input, tsah::ConfigError for more than 16 representative frames.
// prims must outlive the session. Parallel::threads is unused.
std::unique_ptr<RoundSession> makeEmulatedDeviceSession(Bvh bvh, const PrimitiveBoxes& prims,
                                                        const ParallelReinsertionOptimizer::Config& config,
                                                        const ParallelReinsertionOptimizer::Parallel& parallel);

// ParallelReinsertionOptimizer's loop over an emulated device session. deviceBytes (optional)
// receives the bytes the GPU optimizer's own buffers reach on this input: the same allocations,
// counted on the host (CUB's sort buffers and scratch and the threads' local memory come on top).
InsertionOptimizer::Result optimizeEmulatedDevice(Bvh bvh, const PrimitiveBoxes& prims,
                                                  const ParallelReinsertionOptimizer::Config& config,
                                                  const ParallelReinsertionOptimizer::Parallel& parallel,
                                                  const LeafCollapser* collapse = nullptr,
                                                  std::size_t* deviceBytes = nullptr);

}  // namespace tsah
