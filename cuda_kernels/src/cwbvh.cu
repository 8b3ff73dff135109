// The compressed 8-wide BVH on the device: the per-frame refit + re-quantization and the traversal.
// Both run libtsah's TSAH_HD code (cwbvh_quantize.hpp: the planes and the union; cwbvh_layout.hpp:
// cwbvhClosestHit/AnyHit, the box test of ray.hpp and the triangle test of woop.hpp), compiled
// with -fmad=false like the rest of the per-frame path, so nodes equal tsah::refitCwbvh's and hits
// the CPU reference traversal's.
#include "cwbvh_kernels.hpp"
#include "cwbvh_lanes.cuh"
#include "launch.hpp"
#include "triangle_boxes.cuh"


namespace tsah::cuda::detail {

namespace {

__device__ __forceinline__ Aabb loadBoxL2(const Aabb* b) {
  // Written earlier in this launch by another warp of the block (the top levels): read through L2,
  // never a stale L1 line.
  const float* f = reinterpret_cast<const float*>(b);
  Aabb box;
  box.lo = {__ldcg(f), __ldcg(f + 1), __ldcg(f + 2)};
  box.hi = {__ldcg(f + 3), __ldcg(f + 4), __ldcg(f + 5)};
  return box;
}

__device__ __forceinline__ void storeBox(Aabb* b, const Aabb& box) {
  float* f = reinterpret_cast<float*>(b);
  f[0] = box.lo.x, f[1] = box.lo.y, f[2] = box.lo.z, f[3] = box.hi.x, f[4] = box.hi.y, f[5] = box.hi.z;
}

// Words 3-7 of a node (exponents and triCount, childBase, triBase, meta[8]): what the refit reads.
__device__ __forceinline__ CwbvhNodeWords loadRefitWords(const CwbvhNode* __restrict__ nodes, uint32_t node, bool valid) {
  CwbvhNodeWords n{};
  if (valid) {
    n.w[3] = __ldg(reinterpret_cast<const uint32_t*>(nodes + node) + 3);
    const uint4 v = __ldg(reinterpret_cast<const uint4*>(nodes + node) + 1);
    n.w[4] = v.x, n.w[5] = v.y, n.w[6] = v.z, n.w[7] = v.w;
  }
  return n;
}

// The box of the leaf in `slot` (its meta byte `meta`): it ends where the node's next leaf
// begins, or at triCount.
__device__ __forceinline__ Aabb slotLeafBox(const CwbvhNodeWords& n, uint32_t slot, uint32_t meta,
                                            const uint32_t* __restrict__ slotVertices,
                                            const float* __restrict__ positions) {
  const uint32_t first = meta & 0x3fu;
  return leafBox(n.w[5] + first, n.leafEnd(slot, n.leafSlots()) - first, slotVertices, positions);
}

// The refit and re-quantization of one node by 8 aligned lanes of a warp (lane s: slot s), every
// lane of the warp taking part (the shuffles); `valid` false for lanes without a node. Each lane
// forms its slot's exact box: an interior child's union (nodeBoxes, written by the child's own
// group earlier), a leaf child's box (leafBoxOf(meta): from its triangles, or computed earlier),
// nothing for an empty slot. The lanes then form the node's grid (cwbvhGridLanes: the same bits as
// tsah::refitCwbvh) and each quantizes its own slot. Words 0 (p, e; triCount kept) and 2-4 (qlo,
// qhi) are rewritten; word 1 (bases, meta) never changes. Slot 0 stores the union as the node's
// box (and the root's).
template <class LeafBoxOf>
__device__ __forceinline__ void refitNodeLanes(CwbvhNode* __restrict__ nodes, Aabb* __restrict__ nodeBoxes,
                                               uint32_t node, bool valid, LeafBoxOf leafBoxOf,
                                               RootInfo* __restrict__ root) {
  const uint32_t slot = threadIdx.x % kCwbvhWidth;
  const CwbvhNodeWords n = loadRefitWords(nodes, node, valid);
  const uint32_t meta = n.metaOf(slot);
  const bool empty = meta == 0;
  const uint32_t rank = cwbvhPopc(n.interiorSlots() & ((1u << slot) - 1u));
  const Aabb mine = (meta & kCwbvhInterior) ? loadBoxL2(nodeBoxes + n.w[4] + rank)
                    : !empty                ? leafBoxOf(n, meta)
                                            : Aabb{};
  const uint32_t occupied = n.interiorSlots() | n.leafSlots();
  const CwbvhLaneGrid g = cwbvhGridLanes(slot, mine, occupied);
  if (!valid) return;
  cwbvhStoreGridLanes(nodes + node, slot, empty, mine, g);
  if (slot == 0) {  // the node's box (byte 15, triCount, and word 1 are kept)
    storeBox(nodeBoxes + node, g.all);
    if (node == 0) root->box = g.all;
  }
}

// Which tree of a batch a block refits (blockIdx.y: member first + y of a batch of trees of one
// topology, BatchStrides apart, each with its own root); a member whose frame is held
// (FrameParams::held) is left as it is. One tree: the default, every stride 0.
struct CwbvhBatchMember {
  uint32_t first = 0;
  uint64_t nodeStride = 0, positionStride = 0, topLeafStride = 0;  // nodes (and node boxes), floats, top leaf boxes
  const FrameParams* frames = nullptr;  // per member (null: none held)

  __device__ __forceinline__ uint32_t index() const { return first + blockIdx.y; }
  // Moves the block's pointers to its member; false for a held member.
  __device__ __forceinline__ bool select(CwbvhNode* __restrict__& nodes, Aabb* __restrict__& nodeBoxes,
                                         const float* __restrict__& positions, RootInfo* __restrict__& root) const {
    const uint32_t b = index();
    if (frames && frames[b].held) return false;
    if (nodes) nodes += b * nodeStride;
    if (nodeBoxes) nodeBoxes += b * nodeStride;
    positions += b * positionStride;
    root += b;
    return true;
  }
};

// One group of nodes of equal height (cwbvhLevels), 8 lanes per node. Each group is one launch:
// no atomics, and a node's interior children were finished by an earlier launch. (The previous
// refit climbed from every leaf with an arrival counter per node and re-quantized in a second
// kernel; on 1M triangles that was 84 + 26 us, latency-bound, against one launch per height here.)
constexpr uint32_t kLevelBlock = 128;  // whole warps: every lane takes part in the shuffles
__global__ void __launch_bounds__(kLevelBlock)
    cwbvhLevelKernel(CwbvhNode* __restrict__ nodes, Aabb* __restrict__ nodeBoxes, const uint32_t* __restrict__ group,
                     uint32_t count, const uint32_t* __restrict__ slotVertices, const float* __restrict__ positions,
                     RootInfo* __restrict__ root, CwbvhBatchMember member) {
  if (!member.select(nodes, nodeBoxes, positions, root)) return;
  const uint32_t item = (blockIdx.x * blockDim.x + threadIdx.x) / kCwbvhWidth;
  const bool valid = item < count;
  const uint32_t slot = threadIdx.x % kCwbvhWidth;
  auto leafBoxOf = [&](const CwbvhNodeWords& n, uint32_t meta) {
    return slotLeafBox(n, slot, meta, slotVertices, positions);
  };
  refitNodeLanes(nodes, nodeBoxes, valid ? __ldg(group + item) : 0u, valid, leafBoxOf, root);
}

// The small groups at the top of the tree (a few nodes each) in one block, a barrier between
// groups, instead of a launch each: groups [firstGroup, groupCount) of `starts` (on the device).
// The leaf boxes of all those nodes come first, all at once (they depend on no group), into
// leafBoxes (8 per node of these groups): each group then waits only for its children's unions,
// not for its leaves' vertex loads.
constexpr uint32_t kTopBlock = 256;
__global__ void __launch_bounds__(kTopBlock)
    cwbvhTopLevelsKernel(CwbvhNode* __restrict__ nodes, Aabb* __restrict__ nodeBoxes,
                         const uint32_t* __restrict__ levelNodes, const uint32_t* __restrict__ starts,
                         uint32_t firstGroup, uint32_t groupCount, Aabb* __restrict__ leafBoxes,
                         const uint32_t* __restrict__ slotVertices, const float* __restrict__ positions,
                         RootInfo* __restrict__ root, CwbvhBatchMember member) {
  if (!member.select(nodes, nodeBoxes, positions, root)) return;
  leafBoxes += member.index() * member.topLeafStride;
  constexpr uint32_t kNodesPerPass = kTopBlock / kCwbvhWidth;
  const uint32_t slot = threadIdx.x % kCwbvhWidth;
  const uint32_t topBegin = __ldg(starts + firstGroup), topEnd = __ldg(starts + groupCount);
  for (uint32_t base = topBegin; base < topEnd; base += kNodesPerPass) {
    const uint32_t item = base + threadIdx.x / kCwbvhWidth;
    if (item >= topEnd) continue;
    const CwbvhNodeWords n = loadRefitWords(nodes, __ldg(levelNodes + item), true);
    const uint32_t meta = n.metaOf(slot);
    if ((meta & 0xc0u) == kCwbvhLeaf) {
      storeBox(leafBoxes + std::size_t(item - topBegin) * kCwbvhWidth + slot,
               slotLeafBox(n, slot, meta, slotVertices, positions));
    }
  }
  __syncthreads();
  for (uint32_t h = firstGroup; h < groupCount; ++h) {
    const uint32_t begin = __ldg(starts + h), end = __ldg(starts + h + 1);
    for (uint32_t base = begin; base < end; base += kNodesPerPass) {
      const uint32_t item = base + threadIdx.x / kCwbvhWidth;
      const bool valid = item < end;
      auto leafBoxOf = [&](const CwbvhNodeWords&, uint32_t) {
        return loadBoxL2(leafBoxes + std::size_t(item - topBegin) * kCwbvhWidth + slot);
      };
      refitNodeLanes(nodes, nodeBoxes, valid ? __ldg(levelNodes + item) : 0u, valid, leafBoxOf, root);
    }
    __syncthreads();  // the group's boxes are visible to the block before its parents read them
  }
}

// A tree that is one leaf: its box is the root box.
__global__ void cwbvhRootLeafKernel(uint32_t first, uint32_t count, const uint32_t* __restrict__ slotVertices,
                                    const float* __restrict__ positions, RootInfo* __restrict__ root,
                                    CwbvhBatchMember member) {
  CwbvhNode* __restrict__ nodes = nullptr;
  Aabb* __restrict__ nodeBoxes = nullptr;
  if (!member.select(nodes, nodeBoxes, positions, root)) return;
  root->box = leafBox(first, count, slotVertices, positions);
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

RootInfo cwbvhRoot(const CwbvhTree& tree) {
  RootInfo r;
  r.box = tree.rootBox;
  r.ref = tree.rootRef;
  r.count = tree.rootCount;
  r.interiorCount = tree.nodeCount();
  r.depth = tree.depth;
  return r;
}

CwbvhRefitPlan makeCwbvhRefitPlan(const CwbvhTree& tree, cudaStream_t stream) {
  CwbvhRefitPlan plan;
  if (isLeafRef(tree.rootRef)) {
    plan.rootLeafFirst = leafFirstSlot(tree.rootRef);
    plan.rootLeafCount = tree.rootCount;
  }
  const CwbvhLevels levels = cwbvhLevels(tree);
  plan.levelNodes = DeviceBuffer<uint32_t>(std::span<const uint32_t>(levels.nodes), stream);
  plan.levelStarts = DeviceBuffer<uint32_t>(std::span<const uint32_t>(levels.starts), stream);
  plan.starts = levels.starts;
  // From the top down, the groups that take at most two passes of the block (32 nodes each) share
  // it: cheaper than a launch each.
  constexpr uint32_t kTopGroupNodes = 2 * kTopBlock / kCwbvhWidth;
  uint32_t top = uint32_t(plan.starts.size()) - 1;
  while (top > 0 && plan.starts[top] - plan.starts[top - 1] <= kTopGroupNodes) --top;
  plan.firstTopGroup = top;
  plan.topLeafBoxes.resize(plan.topLeafBoxCount());
  CUDA_CHECK(cudaStreamSynchronize(stream));  // before `levels` goes
  return plan;
}

namespace {

// The refit's launches for `count` trees from member.first on (a grid row each).
void launchRefitRows(const CwbvhRefitPlan& plan, CwbvhNode* nodes, Aabb* nodeBoxes, Aabb* topLeafBoxes,
                     const uint32_t* slotVertices, const float* positions, RootInfo* roots, uint32_t count,
                     const CwbvhBatchMember& member, cudaStream_t stream) {
  if (plan.rootLeafCount > 0) {  // one leaf, no nodes
    cwbvhRootLeafKernel<<<dim3(1, count), 1, 0, stream>>>(plan.rootLeafFirst, plan.rootLeafCount, slotVertices,
                                                          positions, roots, member);
    CUDA_CHECK_LAUNCH("cwbvhRootLeafKernel");
    return;
  }
  const uint32_t groups = uint32_t(plan.starts.size()) - 1;
  uint32_t h = 0;
  for (; h < groups && h < plan.firstTopGroup; ++h) {
    const uint32_t nodesOfGroup = plan.starts[h + 1] - plan.starts[h];
    const dim3 grid(gridFor(std::size_t(nodesOfGroup) * kCwbvhWidth, kLevelBlock), count);
    cwbvhLevelKernel<<<grid, kLevelBlock, 0, stream>>>(nodes, nodeBoxes, plan.levelNodes.data() + plan.starts[h],
                                                       nodesOfGroup, slotVertices, positions, roots, member);
    CUDA_CHECK_LAUNCH("cwbvhLevelKernel");
  }
  if (h < groups) {
    cwbvhTopLevelsKernel<<<dim3(1, count), kTopBlock, 0, stream>>>(nodes, nodeBoxes, plan.levelNodes.data(),
                                                                   plan.levelStarts.data(), h, groups, topLeafBoxes,
                                                                   slotVertices, positions, roots, member);
    CUDA_CHECK_LAUNCH("cwbvhTopLevelsKernel");
  }
}

}  // namespace

void launchCwbvhRefit(CwbvhRefitPlan& plan, CwbvhNode* nodes, Aabb* nodeBoxes, const uint32_t* slotVertices,
                      const float* positions, RootInfo* root, cudaStream_t stream) {
  launchRefitRows(plan, nodes, nodeBoxes, plan.topLeafBoxes.data(), slotVertices, positions, root, 1,
                  CwbvhBatchMember{}, stream);
}

void launchBatchCwbvhRefit(const CwbvhRefitPlan& plan, CwbvhNode* nodes, Aabb* nodeBoxes, Aabb* topLeafBoxes,
                           const uint32_t* slotVertices, const float* positions, RootInfo* roots,
                           uint32_t batchCount, const BatchStrides& batch, const FrameParams* frames,
                           cudaStream_t stream) {
  forEachBatchChunk(batchCount, [&](uint32_t first, uint32_t count) {
    const CwbvhBatchMember member{first, batch.nodes, batch.positions, plan.topLeafBoxCount(), frames};
    launchRefitRows(plan, nodes, nodeBoxes, topLeafBoxes, slotVertices, positions, roots, count, member, stream);
  });
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
