// The compressed 8-wide BVH on the device: the per-frame refit + re-quantization and the traversal.
// Both run libtsah's TSAH_HD code (cwbvh_layout.hpp: cwbvhQuantize, cwbvhClosestHit/AnyHit, the
// box test of ray.hpp and the triangle test of woop.hpp), compiled with -fmad=false like the rest
// of the per-frame path, so nodes equal tsah::refitCwbvh's and hits the CPU reference traversal's.
#include <cuda/atomic>

#include "cwbvh_kernels.hpp"
#include "launch.hpp"
#include "triangle_boxes.cuh"


namespace tsah::cuda::detail {

namespace {

__device__ __forceinline__ void storeBox(Aabb* b, const Aabb& box) {
  float* f = reinterpret_cast<float*>(b);
  f[0] = box.lo.x, f[1] = box.lo.y, f[2] = box.lo.z, f[3] = box.hi.x, f[4] = box.hi.y, f[5] = box.hi.z;
}

__device__ __forceinline__ Aabb loadBoxL2(const Aabb* b) {
  // Written by other threads of this launch: read through L2, never a stale L1 line.
  const float* f = reinterpret_cast<const float*>(b);
  Aabb box;
  box.lo = {__ldcg(f), __ldcg(f + 1), __ldcg(f + 2)};
  box.hi = {__ldcg(f + 3), __ldcg(f + 4), __ldcg(f + 5)};
  return box;
}

// Pass 1: exact boxes bottom-up. One thread per leaf writes its box into the parent's slot; the
// last child to arrive at a node (atomic counter) writes the union of the node's slots into the
// node's own slot in its parent, and so on up to the root. Only boxes move here (a union per
// node, as cheap as the binary refit); the quantization is pass 2, in parallel over all nodes,
// instead of one thread quantizing every node on its path (the old chain was 3x the binary
// refit's time on Kitchen).
__global__ void cwbvhExactRefitKernel(const CwbvhNode* __restrict__ nodes, Aabb* __restrict__ exact,
                                      const uint32_t* __restrict__ parentSlot, const CwbvhLeaf* __restrict__ leaves,
                                      uint32_t leafCount, const uint32_t* __restrict__ triIndex,
                                      const uint32_t* __restrict__ indices, const float* __restrict__ positions,
                                      uint32_t* __restrict__ counters, RootInfo* __restrict__ root) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= leafCount) return;
  const CwbvhLeaf leaf = leaves[i];
  Aabb box = leafBox(leaf.first, leaf.count, triIndex, indices, positions);
  uint32_t slot = leaf.nodeSlot;
  while (slot != kCwbvhNoParent) {
    const uint32_t node = slot / kCwbvhWidth;
    storeBox(exact + slot, box);
    CwbvhNode n;
    reinterpret_cast<uint4*>(&n)[1] = __ldg(reinterpret_cast<const uint4*>(nodes + node) + 1);  // bases and meta
    uint32_t occupied = 0;
#pragma unroll
    for (uint32_t s = 0; s < kCwbvhWidth; ++s) occupied += n.meta[s] != 0 ? 1u : 0u;
    ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> arrivals(counters[node]);
    if (arrivals.fetch_add(1, ::cuda::memory_order_acq_rel) + 1 != occupied) return;  // a later child finishes it
    Aabb all;  // the union in slot order, exactly as cwbvhQuantize forms it
#pragma unroll
    for (uint32_t s = 0; s < kCwbvhWidth; ++s)
      if (n.meta[s] != 0) all.extend(loadBoxL2(exact + std::size_t(node) * kCwbvhWidth + s));
    box = all;
    slot = parentSlot[node];
  }
  root->box = box;
}

// Pass 2: every node re-quantized from its children's exact boxes, 8 lanes per node (lane s: slot
// s), because one thread quantizing all 48 planes of a node was a long serial chain (14 us on a
// tree of 30 nodes). Every lane forms the node's union from all 8 boxes (shuffled, in slot order:
// the same extends as cwbvhQuantize, so the same bits) and the exponents; each lane then
// quantizes its own slot (cwbvhSlotPlanes). Words 0 (p, e; triCount kept) and 2-4 (qlo, qhi) are
// rewritten; word 1 (bases, meta) never changes.
constexpr uint32_t kQuantizeBlock = 128;  // whole warps: every lane takes part in the shuffles
__global__ void __launch_bounds__(kQuantizeBlock) cwbvhQuantizeKernel(CwbvhNode* __restrict__ nodes,
                                                                      const Aabb* __restrict__ exact,
                                                                      uint32_t nodeCount) {
  const uint32_t thread = blockIdx.x * blockDim.x + threadIdx.x;
  const uint32_t node = thread / kCwbvhWidth, slot = thread % kCwbvhWidth;
  const bool valid = node < nodeCount;
  uint2 metaWords = make_uint2(0u, 0u);  // bytes 24-31: meta[8]
  if (valid) metaWords = __ldg(reinterpret_cast<const uint2*>(nodes + node) + 3);
  const uint32_t metaWord = slot < 4 ? metaWords.x : metaWords.y;
  const bool empty = ((metaWord >> (8u * (slot & 3u))) & 0xffu) == 0;
  Aabb mine;
  if (valid && !empty) mine = exact[std::size_t(node) * kCwbvhWidth + slot];
  Aabb all;
  const uint32_t group = (threadIdx.x & 31u) & ~(kCwbvhWidth - 1u);  // first lane of this node's 8
#pragma unroll
  for (uint32_t s = 0; s < kCwbvhWidth; ++s) {
    Aabb b;
    b.lo = {__shfl_sync(0xffffffffu, mine.lo.x, group + s), __shfl_sync(0xffffffffu, mine.lo.y, group + s),
            __shfl_sync(0xffffffffu, mine.lo.z, group + s)};
    b.hi = {__shfl_sync(0xffffffffu, mine.hi.x, group + s), __shfl_sync(0xffffffffu, mine.hi.y, group + s),
            __shfl_sync(0xffffffffu, mine.hi.z, group + s)};
    const uint32_t m = ((s < 4 ? metaWords.x : metaWords.y) >> (8u * (s & 3u))) & 0xffu;
    if (m != 0) all.extend(b);
  }
  if (!valid) return;
  uint32_t e[3];
  cwbvhGridExponents(all, e);
  const CwbvhSlotPlanes q = cwbvhSlotPlanes(empty, empty ? all : mine, all, e);
  CwbvhNode* n = nodes + node;
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    n->qlo[a][slot] = q.lo[a];
    n->qhi[a][slot] = q.hi[a];
  }
  if (slot == 0) {  // the grid: p and the exponents (byte 15, triCount, is kept)
    n->px = all.lo.x;
    n->py = all.lo.y;
    n->pz = all.lo.z;
    n->ex = uint8_t(e[0]);
    n->ey = uint8_t(e[1]);
    n->ez = uint8_t(e[2]);
  }
}

__device__ __forceinline__ Ray loadRayVec(const Ray* rays, uint32_t i) {
  const float4* p = reinterpret_cast<const float4*>(rays + i);
  const float4 a = __ldg(p), b = __ldg(p + 1);
  return Ray{{a.x, a.y, a.z}, a.w, {b.x, b.y, b.z}, b.w};
}

template <bool AnyHit>
__device__ __forceinline__ void storeResult(const CwbvhTraversal<AnyHit>& t, const CwbvhView& view,
                                            uint32_t i, Hit* __restrict__ hits, uint8_t* __restrict__ occluded) {
  const Hit h = t.result(view);
  if constexpr (AnyHit)
    occluded[i] = h.valid() ? 1 : 0;
  else
    reinterpret_cast<float4*>(hits)[i] = make_float4(h.t, h.u, h.v, __uint_as_float(h.tri));
}

// Persistent threads: a lane whose ray finished idles until at least this many lanes of its warp
// are idle (or all are), then those lanes take new rays together, so that the warp runs one ray
// setup pass for many lanes instead of one per finished lane (Aila and Laine's dynamic fetch).
constexpr int kRefillIdleLanes = 8;  // 8 and 16 measured within 3% of each other (docs/cwbvh.md)

// One thread per ray, or (Persistent) resident threads that take new rays from a global counter
// as theirs finish: lanes of a warp then stay busy while the rays of the warp need different
// numbers of nodes (the lanes taking rays at the same time share one atomic).
template <bool AnyHit, bool Persistent>
__global__ void __launch_bounds__(128) cwbvhTraceKernel(CwbvhView view, const RootInfo* __restrict__ root,
                                                        const Ray* __restrict__ rays, uint32_t count,
                                                        Hit* __restrict__ hits, uint8_t* __restrict__ occluded,
                                                        uint32_t* __restrict__ rayCounter) {
  view.rootBox = root->box;
  CwbvhTraversal<AnyHit> t;
  CwbvhNodeGroup stack[kCwbvhStackSize];
  if constexpr (!Persistent) {
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= count) return;
    if (t.start(view, loadRayVec(rays, i)))
      while (t.step(view, stack)) {
      }
    storeResult(t, view, i, hits, occluded);
  } else {
    uint32_t rayIndex = 0;
    bool live = false;
    for (;;) {
      const unsigned looping = __activemask();
      const unsigned idle = __ballot_sync(looping, !live);
      if (!live && (__popc(idle) >= kRefillIdleLanes || idle == looping)) {
        rayIndex = takeIndices(rayCounter);
        if (rayIndex >= count) break;
        live = t.start(view, loadRayVec(rays, rayIndex));
        if (!live) storeResult(t, view, rayIndex, hits, occluded);
      }
      if (live) {
        live = t.step(view, stack);
        if (!live) storeResult(t, view, rayIndex, hits, occluded);
      }
    }
  }
}

template <bool AnyHit, bool Persistent>
void launchWideTyped(const CwbvhView& view, const RootInfo* root, const Ray* rays, uint32_t count, Hit* hits,
                     uint8_t* occluded, uint32_t* rayCounter, const TraceLaunch& launch, cudaStream_t stream) {
  const unsigned block = 128;  // fixed by __launch_bounds__
  unsigned grid = gridFor(count, block);
  if constexpr (Persistent) {
    const unsigned resident =
        launch.blocks != 0 ? launch.blocks : unsigned(residentBlocks(cwbvhTraceKernel<AnyHit, true>, int(block), 64));
    if (resident < grid) grid = resident;
  }
  cwbvhTraceKernel<AnyHit, Persistent><<<grid, block, 0, stream>>>(view, root, rays, count, hits, occluded, rayCounter);
  CUDA_CHECK_LAUNCH(AnyHit ? "cwbvhTraceKernel<any hit>" : "cwbvhTraceKernel<closest hit>");
}

}  // namespace

void launchCwbvhRefit(CwbvhNode* nodes, uint32_t nodeCount, Aabb* exact, const uint32_t* parentSlot,
                      const CwbvhLeaf* leaves, uint32_t leafCount, const uint32_t* triIndex, const uint32_t* indices,
                      const float* positions, uint32_t* counters, RootInfo* root, cudaStream_t stream) {
  if (leafCount == 0) return;
  const uint32_t block = 128;
  cwbvhExactRefitKernel<<<gridFor(leafCount, block), block, 0, stream>>>(nodes, exact, parentSlot, leaves, leafCount,
                                                                         triIndex, indices, positions, counters, root);
  CUDA_CHECK_LAUNCH("cwbvhExactRefitKernel");
  if (nodeCount == 0) return;  // the tree is one leaf
  cwbvhQuantizeKernel<<<gridFor(std::size_t(nodeCount) * kCwbvhWidth, kQuantizeBlock), kQuantizeBlock, 0, stream>>>(
      nodes, exact, nodeCount);
  CUDA_CHECK_LAUNCH("cwbvhQuantizeKernel");
}

void launchCwbvhTrace(const TraceScene& scene, const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded,
                      uint32_t* rayCounter, const TraceLaunch& launch, cudaStream_t stream) {
  if (count == 0) return;
  const CwbvhView view = cwbvhView(scene);
  if (hits && launch.persistent)
    launchWideTyped<false, true>(view, scene.root, rays, count, hits, nullptr, rayCounter, launch, stream);
  else if (hits)
    launchWideTyped<false, false>(view, scene.root, rays, count, hits, nullptr, rayCounter, launch, stream);
  else if (launch.persistent)
    launchWideTyped<true, true>(view, scene.root, rays, count, nullptr, occluded, rayCounter, launch, stream);
  else
    launchWideTyped<true, false>(view, scene.root, rays, count, nullptr, occluded, rayCounter, launch, stream);
}

}  // namespace tsah::cuda::detail
