#pragma once
// Small helpers for kernel launches (CUDA sources only).
#include <cuda_runtime_api.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "tsah_cuda/cuda_check.hpp"

namespace tsah::cuda::detail {

// Blocks of `block` threads covering n items, capped at what a 1D grid allows.
inline unsigned gridFor(std::size_t n, unsigned block) {
  const std::size_t blocks = (n + block - 1) / block;
  return static_cast<unsigned>(blocks == 0 ? 1 : (blocks > 0x7fffffffu ? 0x7fffffffu : blocks));
}

// A launch's grid has at most 65535 rows: a larger batch goes in chunks of rows, f(first, count).
template <class F>
void forEachBatchChunk(uint32_t batchCount, F&& f) {
  constexpr uint32_t kMaxRows = 65535;
  for (uint32_t first = 0; first < batchCount; first += kMaxRows) f(first, std::min(kMaxRows, batchCount - first));
}

// Blocks of a persistent kernel that are all resident at once on the current device (the
// occupancy calculator's blocks per multiprocessor, at most maxPerSm): kernels that wait for each
// other's blocks (work queues, grid barriers) must never launch more.
template <typename Kernel>
int residentBlocks(Kernel kernel, int blockSize, int maxPerSm) {
  int device = 0, sms = 0, perSm = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&perSm, kernel, blockSize, 0));
  return std::max(1, sms * std::clamp(perSm, 1, maxPerSm));
}

#if defined(__CUDACC__)
// The lanes of a warp that call this together take consecutive indices from *counter with one
// atomic per warp: the persistent traversals' ray fetch (Aila and Laine) and the renderer's list
// of pixels with a surface. The callers are the active lanes, named with __activemask(), so no
// code assumes lock-step execution.
__device__ __forceinline__ uint32_t takeIndices(uint32_t* counter) {
  const unsigned mask = __activemask();
  const uint32_t lane = threadIdx.x & 31u;
  const int leader = __ffs(mask) - 1;
  uint32_t base = 0;
  if (int(lane) == leader) base = atomicAdd(counter, uint32_t(__popc(mask)));
  base = __shfl_sync(mask, base, leader);
  return base + uint32_t(__popc(mask & ((1u << lane) - 1u)));
}
#endif

}  // namespace tsah::cuda::detail
