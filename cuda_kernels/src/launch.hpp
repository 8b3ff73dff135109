#pragma once
// Small helpers for kernel launches (CUDA sources only).
#include <cstddef>
#include <cstdint>

#include "tsah_cuda/cuda_check.hpp"

namespace tsah::cuda::detail {

// Blocks of `block` threads covering n items, capped at what a 1D grid allows.
inline unsigned gridFor(std::size_t n, unsigned block) {
  const std::size_t blocks = (n + block - 1) / block;
  return static_cast<unsigned>(blocks == 0 ? 1 : (blocks > 0x7fffffffu ? 0x7fffffffu : blocks));
}

}  // namespace tsah::cuda::detail
