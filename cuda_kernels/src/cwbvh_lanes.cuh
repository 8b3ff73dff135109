#pragma once
// Steps on one compressed 8-wide node done by 8 aligned lanes of a warp, a lane per child slot
// (lane s: slot s): shared by the per-frame refit (cwbvh.cu) and the conversion of the rebuilt
// trees (cwbvh_rebuild.cu). Each gives the bits of libtsah's serial code (cwbvh_quantize.hpp).
#include <cstdint>

#include "tsah/layout/cwbvh_quantize.hpp"

namespace tsah::cuda::detail {

// The first lane of the calling lane's group of 8 (within its warp).
__device__ __forceinline__ uint32_t cwbvhGroupFirstLane() { return (threadIdx.x & 31u) & ~(kCwbvhWidth - 1u); }

// A box from another lane of the same group of 8 (the lanes named in mask all call it): from
// member `source`, or from the member whose index differs from this one's by xor `laneXor`.
template <class Get>
__device__ __forceinline__ Aabb cwbvhBoxFrom(const Aabb& b, Get get) {
  Aabb r;
  r.lo = {get(b.lo.x), get(b.lo.y), get(b.lo.z)};
  r.hi = {get(b.hi.x), get(b.hi.y), get(b.hi.z)};
  return r;
}
__device__ __forceinline__ Aabb cwbvhShflBox(uint32_t mask, const Aabb& b, uint32_t source) {
  return cwbvhBoxFrom(b, [&](float v) { return __shfl_sync(mask, v, int(source), int(kCwbvhWidth)); });
}
__device__ __forceinline__ Aabb cwbvhShflXorBox(uint32_t mask, const Aabb& b, uint32_t laneXor) {
  return cwbvhBoxFrom(b, [&](float v) { return __shfl_xor_sync(mask, v, int(laneXor), int(kCwbvhWidth)); });
}

// The node's grid: the union of the occupied slots' exact boxes and its exponents.
struct CwbvhLaneGrid {
  Aabb all;
  uint32_t e[3];
};

// `mine`: this lane's exact box (read only where bit `slot` of `occupied` is set). The union is
// formed as cwbvhChildUnion forms it: three exchanges, each joining the lower and the upper half of
// an aligned block of slots, so its bits are the host's where boxes tie at -0 / +0 or hold a NaN;
// then lanes 0-2 of the group form one exponent each (cwbvhGridExponents) and the others take them
// from there. Every lane of the warp must call it (full-warp shuffles).
__device__ __forceinline__ CwbvhLaneGrid cwbvhGridLanes(uint32_t slot, const Aabb& mine, uint32_t occupied) {
  CwbvhPartialUnion part{mine, ((occupied >> slot) & 1u) != 0};
#pragma unroll
  for (uint32_t width = 1; width < kCwbvhWidth; width *= 2) {
    CwbvhPartialUnion other;
    other.box = cwbvhShflXorBox(0xffffffffu, part.box, width);
    const uint32_t otherFirst = (slot ^ width) & ~(width - 1u);
    other.any = ((occupied >> otherFirst) & ((1u << width) - 1u)) != 0;
    const bool upperHalf = (slot & width) != 0;  // the other half is the lower one
    part = cwbvhJoin({cwbvhSelectBox(upperHalf, other.box, part.box), upperHalf ? other.any : part.any},
                     {cwbvhSelectBox(upperHalf, part.box, other.box), upperHalf ? part.any : other.any});
  }
  CwbvhLaneGrid g;
  g.all = part.box;
  const uint32_t group = cwbvhGroupFirstLane();
  const float lo = slot == 1 ? g.all.lo.y : slot == 2 ? g.all.lo.z : g.all.lo.x;
  const float hi = slot == 1 ? g.all.hi.y : slot == 2 ? g.all.hi.z : g.all.hi.x;
  const uint32_t own = tsah::detail::cwbvhExponent(lo, hi);
  g.e[0] = __shfl_sync(0xffffffffu, own, group);
  g.e[1] = __shfl_sync(0xffffffffu, own, group + 1);
  g.e[2] = __shfl_sync(0xffffffffu, own, group + 2);
  return g;
}

// Stores this lane's planes (an empty slot gets cwbvhSlotPlanes' empty planes) and, from lane 0 of
// the group, the grid (p and the exponents) into `out`.
__device__ __forceinline__ void cwbvhStoreGridLanes(CwbvhNode* out, uint32_t slot, bool empty, const Aabb& mine,
                                                    const CwbvhLaneGrid& g) {
  const Aabb slotBox = cwbvhSelectBox(empty, g.all, mine);  // (a select of references put both boxes in local memory)
  const CwbvhSlotPlanes q = cwbvhSlotPlanes(empty, slotBox, g.all, g.e);
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    out->qlo[a][slot] = q.lo[a];
    out->qhi[a][slot] = q.hi[a];
  }
  if (slot == 0) {
    out->px = g.all.lo.x;
    out->py = g.all.lo.y;
    out->pz = g.all.lo.z;
    out->ex = uint8_t(g.e[0]);
    out->ey = uint8_t(g.e[1]);
    out->ez = uint8_t(g.e[2]);
  }
}

}  // namespace tsah::cuda::detail
