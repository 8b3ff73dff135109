#pragma once
// Triangle boxes read from the current frame's positions, shared by the refit kernels (binary and
// compressed layouts) and the rebuilds' box pass: one way to load a vertex and bound a triangle.
#include <cstddef>
#include <cstdint>

#include "tsah/aabb.hpp"

namespace tsah::cuda::detail {

__device__ __forceinline__ Vec3 loadVertex(const float* __restrict__ p, uint32_t v) {
  return {__ldg(p + 3 * std::size_t(v)), __ldg(p + 3 * std::size_t(v) + 1), __ldg(p + 3 * std::size_t(v) + 2)};
}

// Extends `box` by the vertices of triangle `tri` (three vertex ids in `indices`), in vertex order
// (the order the CPU refit uses, so boxes agree bit for bit).
__device__ __forceinline__ void extendByTriangle(Aabb& box, const uint32_t* __restrict__ indices,
                                                 const float* __restrict__ positions, uint32_t tri) {
  const uint32_t* v = indices + 3 * std::size_t(tri);
  box.extend(loadVertex(positions, __ldg(v)));
  box.extend(loadVertex(positions, __ldg(v + 1)));
  box.extend(loadVertex(positions, __ldg(v + 2)));
}

// The box of the leaf holding slots [first, first + count) of `triIndex`.
__device__ __forceinline__ Aabb leafBox(uint32_t first, uint32_t count, const uint32_t* __restrict__ triIndex,
                                        const uint32_t* __restrict__ indices, const float* __restrict__ positions) {
  Aabb box;
  for (uint32_t s = first; s < first + count; ++s) extendByTriangle(box, indices, positions, __ldg(triIndex + s));
  return box;
}

}  // namespace tsah::cuda::detail
