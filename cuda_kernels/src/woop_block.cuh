#pragma once
// A block's Woop triangles stored through shared memory: each store instruction of a warp writes
// 512 contiguous bytes (a thread's three 16-byte rows, stored directly, left each instruction a
// third of every sector it touched). Shared by the refits' Woop pass and the keyed pose update.
#include <cstdint>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah::cuda::detail {

constexpr uint32_t kWoopBlock = 128;

// Slots [first, first + kWoopBlock) below `slots`, one thread each (blockDim.x == kWoopBlock; every
// thread of the block calls it): vertices(s, v) fills the three vertices of slot s.
template <class Vertices>
__device__ __forceinline__ void woopBlock(uint32_t first, uint32_t slots, Vertices vertices,
                                          WoopTriangle* __restrict__ woop) {
  __shared__ float4 rows[3 * kWoopBlock];
  const uint32_t s = first + threadIdx.x;
  if (s < slots) {
    Vec3 v[3];
    vertices(s, v);
    const WoopTriangle w = makeWoopTriangle(v[0], v[1], v[2]);
    rows[3 * threadIdx.x] = make_float4(w.r0.x, w.r0.y, w.r0.z, w.r0.w);
    rows[3 * threadIdx.x + 1] = make_float4(w.r1.x, w.r1.y, w.r1.z, w.r1.w);
    rows[3 * threadIdx.x + 2] = make_float4(w.r2.x, w.r2.y, w.r2.z, w.r2.w);
  }
  __syncthreads();
  const uint32_t rowCount = 3 * (slots - first < kWoopBlock ? slots - first : kWoopBlock);
  float4* out = reinterpret_cast<float4*>(woop + first);
  for (uint32_t r = threadIdx.x; r < rowCount; r += kWoopBlock) out[r] = rows[r];
}

}  // namespace tsah::cuda::detail
