#pragma once
// Triangle boxes read from the current frame's positions, shared by the refit kernels (binary and
// compressed layouts) and the rebuilds' box pass: one way to load a vertex and bound a triangle.
#include <cstddef>
#include <cstdint>

#include "tsah/core/aabb.hpp"

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

// The box of the leaf holding slots [first, first + count), in slot and vertex order, from the
// slots' vertex indices (slotVertices: 3 per slot, tsah::slotVertexIndices). Four triangles at a
// time: their vertex ids, then their vertices are loaded together, so a leaf waits for two memory
// round trips per four triangles instead of per one. (Writing the slots' Woop triangles here as
// well, from the vertices at hand, made the latency-bound refit slower than the separate pass: 1M
// triangles 0.150 -> 0.163 ms when measured.)
__device__ __forceinline__ Aabb leafBox(uint32_t first, uint32_t count, const uint32_t* __restrict__ slotVertices,
                                        const float* __restrict__ positions) {
  constexpr uint32_t kBatch = 4;
  Aabb box;
  for (uint32_t s = first; s < first + count; s += kBatch) {
    const uint32_t n = first + count - s < kBatch ? first + count - s : kBatch;
    uint32_t v[kBatch][3];
    Vec3 p[kBatch][3];
#pragma unroll
    for (uint32_t k = 0; k < kBatch; ++k)
#pragma unroll
      for (int c = 0; c < 3; ++c) v[k][c] = k < n ? __ldg(slotVertices + 3 * std::size_t(s + k) + c) : 0u;
#pragma unroll
    for (uint32_t k = 0; k < kBatch; ++k)
#pragma unroll
      for (int c = 0; c < 3; ++c) p[k][c] = k < n ? loadVertex(positions, v[k][c]) : Vec3{0.0f, 0.0f, 0.0f};
#pragma unroll
    for (uint32_t k = 0; k < kBatch; ++k)
#pragma unroll
      for (int c = 0; c < 3; ++c)
        if (k < n) box.extend(p[k][c]);
  }
  return box;
}

}  // namespace tsah::cuda::detail
