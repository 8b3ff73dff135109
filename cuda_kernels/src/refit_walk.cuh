#pragma once
// The bottom-up refit walk shared by the flat runtime's refit (triangle leaves) and the two-level
// runtime's refits (pose BLAS, TLAS over instance boxes): a leaf's thread writes its box into the
// parent's child slot; the second thread to arrive at a node has both child boxes and carries on
// upwards. refitUpwards walks through global memory (any tree size, one thread per leaf of a grid);
// partRefit keeps the walk of a part of a tree (tsah::splitForBlockRefit) in one block's shared memory.
#include <cuda/atomic>

#include "device_types.hpp"

namespace tsah::cuda::detail {

// A child box into a node's twelve box floats (gpu_layout.hpp: n0xy, n1xy, nz; child 1's x/y start
// at float 4, z boxes at 8 / 10), in global memory or (volatile) in shared memory.
template <class Float>
__device__ __forceinline__ void storeChildBox(Float* f, int side, const Aabb& b) {
  const int xy = side == 0 ? 0 : 4, z = side == 0 ? 8 : 10;
  f[xy + 0] = b.lo.x;
  f[xy + 1] = b.hi.x;
  f[xy + 2] = b.lo.y;
  f[xy + 3] = b.hi.y;
  f[z + 0] = b.lo.z;
  f[z + 1] = b.hi.z;
}

__device__ __forceinline__ void writeChildBox(GpuBvhNode* node, int side, const Aabb& b) {
  storeChildBox(reinterpret_cast<float*>(node), side, b);
}

__device__ __forceinline__ Aabb readChildBox(const GpuBvhNode* node, int side) {
  // Written by another thread of this launch: read through L2 (never a stale L1 line).
  const float* f = reinterpret_cast<const float*>(node);
  const int xy = side == 0 ? 0 : 4, z = side == 0 ? 8 : 10;
  Aabb b;
  b.lo = {__ldcg(f + xy + 0), __ldcg(f + xy + 2), __ldcg(f + z + 0)};
  b.hi = {__ldcg(f + xy + 1), __ldcg(f + xy + 3), __ldcg(f + z + 1)};
  return b;
}

// From the leaf at parentSlot with box `box` up to where a sibling is still missing, or to the root
// (root->box). counters: one per interior node, zero before the launch.
__device__ __forceinline__ void refitUpwards(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                                             uint32_t slot, Aabb box, uint32_t* __restrict__ counters,
                                             RootInfo* __restrict__ root) {
  while (slot != kNoParent) {
    const uint32_t node = slot >> 1;
    const int side = int(slot & 1);
    writeChildBox(nodes + node, side, box);
    ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> arrivals(counters[node]);
    if (arrivals.fetch_add(1, ::cuda::memory_order_acq_rel) == 0) return;  // the sibling finishes the node
    box.extend(readChildBox(nodes + node, 1 - side));
    slot = nodeParent[node];
  }
  root->box = box;
}

// storeChildBox's box read back from a node's floats in shared memory.
__device__ __forceinline__ Aabb loadSharedChildBox(volatile const float* node, int side) {
  const int xy = side == 0 ? 0 : 4, z = side == 0 ? 8 : 10;
  return Aabb{{node[xy + 0], node[xy + 2], node[z + 0]}, {node[xy + 1], node[xy + 3], node[z + 1]}};
}

// One block refits one part of a tree split by tsah::splitForBlockRefit (a subtree, the top above
// the subtrees, or a small tree whole): arrivals, parents and child boxes are kept in shared memory,
// so a level of the walk costs shared-memory latency instead of refitUpwards' round trips to L2.
// The nodes' boxes are written at the end, twelve floats per node by consecutive threads (a
// subtree's nodes are consecutive in the tree: the stores coalesce). prologue() runs before the
// walk, beside the shared memory's set-up, with a barrier after both (the pose kernel computes its
// triangles there). boxOf(item) gives an item's box (a leaf's, or a subtree part's root box); the
// part's root box goes to *exitBox. The boxes equal refitUpwards' (min and max are exact, so the
// order of the extends does not matter). shared: partWalkWords(part.nodeCount) words (device_types.hpp)
// and the caller's own after them.
template <class Prologue, class ItemBoxOf>
__device__ void partRefit(GpuBvhNode* __restrict__ nodes, const RefitPartsView& view, const RefitPart& part,
                          Prologue prologue, ItemBoxOf boxOf, Aabb* exitBox, uint32_t* shared) {
  uint32_t* counters = shared;
  uint32_t* parents = shared + part.nodeCount;
  uint32_t* globals = shared + 2 * std::size_t(part.nodeCount);
  volatile float* boxes = reinterpret_cast<volatile float*>(shared + 3 * std::size_t(part.nodeCount));
  // The node indices too: read here beside the parents, not one dependent load per float at the end.
  for (uint32_t n = threadIdx.x; n < part.nodeCount; n += blockDim.x) {
    counters[n] = 0;
    parents[n] = __ldg(view.parentSlot + part.firstNode + n);
    globals[n] = __ldg(view.globalNode + part.firstNode + n);
  }
  prologue();
  __syncthreads();
  for (uint32_t i = threadIdx.x; i < part.itemCount; i += blockDim.x) {
    const RefitPartItem item = view.items[part.firstItem + i];
    Aabb box = boxOf(item);
    uint32_t slot = item.parentSlot;
    bool reachedExit = true;
    while (slot != kPartExitSlot) {
      const uint32_t node = slot >> 1;
      const int side = int(slot & 1);
      storeChildBox(boxes + 12 * std::size_t(node), side, box);
      __threadfence_block();  // the box before the arrival: the sibling reads it after its own
      if (atomicAdd(counters + node, 1u) == 0) {
        reachedExit = false;  // the sibling finishes the node
        break;
      }
      __threadfence_block();
      box.extend(loadSharedChildBox(boxes + 12 * std::size_t(node), 1 - side));
      slot = parents[node];
    }
    if (reachedExit) *exitBox = box;
  }
  __syncthreads();
  for (uint32_t k = threadIdx.x; k < 12 * part.nodeCount; k += blockDim.x)
    reinterpret_cast<float*>(nodes + globals[k / 12])[k % 12] = boxes[k];
}

}  // namespace tsah::cuda::detail
