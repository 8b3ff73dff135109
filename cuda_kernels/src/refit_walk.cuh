#pragma once
// The bottom-up refit walk shared by the flat runtime's refit (triangle leaves) and the two-level
// runtime's refits (pose BLAS, TLAS over instance boxes): a leaf's thread writes its box into the
// parent's child slot; the second thread to arrive at a node has both child boxes and carries on
// upwards. refitUpwards walks through global memory (any tree size, one thread per leaf of a grid);
// blockRefit keeps a tree's walk, or a subtree's, in one block's shared memory.
#include <cuda/atomic>

#include "device_types.hpp"

namespace tsah::cuda::detail {

__device__ __forceinline__ void writeChildBox(GpuBvhNode* node, int side, const Aabb& b) {
  float* f = reinterpret_cast<float*>(node);
  // Layout (gpu_layout.hpp): n0xy, n1xy, nz; child 1's x/y start at float 4, z boxes at 8 / 10.
  const int xy = side == 0 ? 0 : 4, z = side == 0 ? 8 : 10;
  f[xy + 0] = b.lo.x;
  f[xy + 1] = b.hi.x;
  f[xy + 2] = b.lo.y;
  f[xy + 3] = b.hi.y;
  f[z + 0] = b.lo.z;
  f[z + 1] = b.hi.z;
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

// One block refits one treelet (device_types.hpp: a whole small tree, a character's BLAS or a TLAS
// over some thousand instances, or a subtree of a larger one). Arrival counters and child boxes are
// kept in shared memory, written to the nodes at the end, so a level of the walk costs shared-memory
// latency instead of refitUpwards' round trips to L2. A walk that leaves the treelet (its root's
// parent, or a leaf whose parent lies above every treelet) carries on by refitUpwards, with
// topCounters (one per interior node, zero before the launch; unused when the treelet is the whole
// tree): the nodes above the treelets are written only there, the treelet's only by its block.
// leafBoxOf(leaf) gives a leaf's box; the boxes equal refitUpwards' (the same extends in the same
// order). shared: blockRefitBytes(treelet's interior count) bytes (device_types.hpp).
template <class LeafBoxOf>
__device__ void blockRefit(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                           const LeafRecord* __restrict__ leaves, const Treelet& part, LeafBoxOf leafBoxOf,
                           uint32_t* __restrict__ topCounters, RootInfo* __restrict__ root, uint32_t* shared) {
  const uint32_t interiorCount = part.nodeEnd - part.nodeBegin;
  uint32_t* counters = shared;
  volatile float* boxes = reinterpret_cast<volatile float*>(shared + interiorCount);
  for (uint32_t n = threadIdx.x; n < interiorCount; n += blockDim.x) counters[n] = 0;
  __syncthreads();
  for (uint32_t i = part.leafBegin + threadIdx.x; i < part.leafEnd; i += blockDim.x) {
    const LeafRecord leaf = leaves[i];
    Aabb box = leafBoxOf(leaf);
    uint32_t slot = leaf.parentSlot;
    while (true) {
      if (slot == kNoParent) {
        root->box = box;
        break;
      }
      const uint32_t node = (slot >> 1) - part.nodeBegin;  // wraps past interiorCount below the treelet
      if (node >= interiorCount) {
        refitUpwards(nodes, nodeParent, slot, box, topCounters, root);
        break;
      }
      const int side = int(slot & 1);
      volatile float* mine = boxes + 12 * std::size_t(node) + 6 * side;
      mine[0] = box.lo.x, mine[1] = box.lo.y, mine[2] = box.lo.z;
      mine[3] = box.hi.x, mine[4] = box.hi.y, mine[5] = box.hi.z;
      __threadfence_block();  // the box before the arrival: the sibling reads it after its own
      if (atomicAdd(counters + node, 1u) == 0) break;  // the sibling finishes the node
      __threadfence_block();
      volatile const float* other = boxes + 12 * std::size_t(node) + 6 * (1 - side);
      box.extend(Aabb{{other[0], other[1], other[2]}, {other[3], other[4], other[5]}});
      slot = nodeParent[part.nodeBegin + node];
    }
  }
  __syncthreads();
  for (uint32_t k = threadIdx.x; k < 2 * interiorCount; k += blockDim.x) {
    volatile const float* b = boxes + 6 * std::size_t(k);
    writeChildBox(nodes + part.nodeBegin + k / 2, int(k & 1), Aabb{{b[0], b[1], b[2]}, {b[3], b[4], b[5]}});
  }
}

}  // namespace tsah::cuda::detail
