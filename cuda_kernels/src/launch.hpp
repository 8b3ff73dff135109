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

}  // namespace tsah::cuda::detail
