// The two-level runtime's kernels: instance world boxes, the TLAS refit over them, and the trace
// through instances: the TLAS and each BLAS by the binary layout's device loop (bvh2_traversal.cuh).
// Compiled with -fmad=false (see CMakeLists.txt): boxes and hits round as on the CPU.
#include "bvh2_traversal.cuh"
#include "launch.hpp"
#include "refit_walk.cuh"
#include "triangle_boxes.cuh"
#include "tsah/core/instance_transform.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda::detail {

namespace {

__global__ void instanceBoxesKernel(const InstanceState* __restrict__ instances, const BlasView* __restrict__ views,
                                    uint32_t count, Aabb* __restrict__ boxes) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const InstanceState& inst = instances[i];
  boxes[i] = transformBoxRows(views[inst.view].root->box, inst.world);
}

// The flat runtime's refit walk with instance boxes as the leaves' content.
__global__ void tlasRefitKernel(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                                const LeafRecord* __restrict__ leaves, uint32_t leafCount,
                                const uint32_t* __restrict__ triIndex, const Aabb* __restrict__ instanceBoxes,
                                uint32_t* __restrict__ counters, RootInfo* __restrict__ root) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= leafCount) return;
  const LeafRecord leaf = leaves[i];
  Aabb box;
  for (uint32_t s = leaf.first; s < leaf.first + leaf.count; ++s) box.extend(instanceBoxes[triIndex[s]]);
  refitUpwards(nodes, nodeParent, leaf.parentSlot, box, counters, root);
}

// Block refits: threads per pose's tree, and for the TLAS (one block for the whole frame's instances).
constexpr uint32_t kBlockThreads = 512;
constexpr uint32_t kTlasBlockThreads = 1024;

// One block per pose of a group (blockIdx.x): its Woop triangles and its refit, both from the
// positions the batched interpolation wrote before this launch.
__global__ void __launch_bounds__(kBlockThreads)
    poseBlasBlockKernel(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                        const LeafRecord* __restrict__ leaves, uint32_t leafCount, uint32_t interiorCount,
                        const uint32_t* __restrict__ slotVertices, uint32_t slots, const float* __restrict__ positions,
                        WoopTriangle* __restrict__ woop, RootInfo* __restrict__ roots, BatchStrides batch) {
  extern __shared__ uint32_t shared[];
  const uint32_t b = blockIdx.x;
  const float* own = positions + b * batch.positions;
  WoopTriangle* ownWoop = woop + b * batch.woop;
  for (uint32_t s = threadIdx.x; s < slots; s += blockDim.x) {
    const uint32_t* tri = slotVertices + 3 * std::size_t(s);
    ownWoop[s] = makeWoopTriangle(loadVertex(own, __ldg(tri)), loadVertex(own, __ldg(tri + 1)),
                                  loadVertex(own, __ldg(tri + 2)));
  }
  const auto leafBoxOf = [&](const LeafRecord& leaf) { return leafBox(leaf.first, leaf.count, slotVertices, own); };
  blockRefit(nodes + b * batch.nodes, nodeParent, leaves, leafCount, interiorCount, leafBoxOf, roots + b, shared);
}

// One block: every instance's world box, then the TLAS refit over them.
__global__ void __launch_bounds__(kTlasBlockThreads)
    tlasBlockKernel(const InstanceState* __restrict__ instances, const BlasView* __restrict__ views, uint32_t count,
                    Aabb* instanceBoxes, GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                    const LeafRecord* __restrict__ leaves, uint32_t leafCount, uint32_t interiorCount,
                    const uint32_t* __restrict__ triIndex, RootInfo* __restrict__ root) {
  extern __shared__ uint32_t shared[];
  for (uint32_t i = threadIdx.x; i < count; i += blockDim.x)
    instanceBoxes[i] = transformBoxRows(views[instances[i].view].root->box, instances[i].world);
  __syncthreads();  // the boxes of other threads, read below (plain loads: written in this launch)
  const auto leafBoxOf = [&](const LeafRecord& leaf) {
    Aabb box;
    for (uint32_t s = leaf.first; s < leaf.first + leaf.count; ++s) box.extend(instanceBoxes[triIndex[s]]);
    return box;
  };
  blockRefit(nodes, nodeParent, leaves, leafCount, interiorCount, leafBoxOf, root, shared);
}

// What the binary layout's device loop (bvh2_traversal.cuh) reads of the TLAS: its nodes as a
// flat tree's, and a slot's "triangle" is its instance's BLAS, traced by the same loop with the ray
// in instance space. prim: the BLAS triangle of the last hit the loop accepted (the loop accepts
// every hit a slot test reports: it is nearer than the ray's current end).
template <bool AnyHit>
struct TlasLoopFrame {
  TlasScene scene;
  mutable uint32_t prim = kNoHit;
};

template <bool AnyHit>
__device__ __forceinline__ void loadBvh2Node(const TlasLoopFrame<AnyHit>& f, int32_t ref, float4& n0xy, float4& n1xy,
                                             float4& nz, int4& refs) {
  const float4* n = reinterpret_cast<const float4*>(f.scene.nodes + ref);
  n0xy = __ldg(n), n1xy = __ldg(n + 1), nz = __ldg(n + 2);
  refs = __ldg(reinterpret_cast<const int4*>(n + 3));
}

template <bool AnyHit>
__device__ __forceinline__ uint32_t slotTriangle(const TlasLoopFrame<AnyHit>& f, uint32_t s) {
  return __ldg(f.scene.triIndex + s);
}

// Slot s's instance: its BLAS (AnyHit: whether anything is hit before tmax).
template <bool AnyHit>
__device__ __forceinline__ bool intersectBvh2Slot(const TlasLoopFrame<AnyHit>& f, const Ray& ray, const RayPrep& prep,
                                                  uint32_t s, float tmax, float& t, float& u, float& v) {
  const uint32_t instance = slotTriangle(f, s);
  const InstanceState& inst = f.scene.instances[instance];
  // The instance's own box before its transform and BLAS (as the CPU runtime's TLAS frame).
  float entry;
  if (!inst.visible || !intersectBox(prep, f.scene.instanceBoxes[instance], ray.tmin, tmax, entry)) return false;
  const BlasView& view = f.scene.views[inst.view];
  TraceScene blas;
  blas.nodes = view.nodes;
  blas.woop = view.woop;
  blas.triIndex = view.triIndex;
  blas.indices = view.indices;
  blas.positions = view.positions;
  blas.root = view.root;
  const RootInfo root = *view.root;
  const Ray local = rayInInstance(inst.toInstance, ray, tmax);
  if constexpr (AnyHit) {
    if (!bvh2AnyHit(blas, root, local)) return false;
    t = tmax;
    u = v = 0.0f;
    return true;
  } else {
    const Hit h = bvh2ClosestHit(blas, root, local);
    if (!h.valid() || !(h.t < tmax)) return false;
    t = h.t;
    u = h.u;
    v = h.v;
    f.prim = h.tri;
    return true;
  }
}

template <bool AnyHit>
__global__ void __launch_bounds__(128) twoLevelTraceKernel(TlasScene scene, const Ray* __restrict__ rays,
                                                           uint32_t count, InstanceHit* __restrict__ hits,
                                                           uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  TlasLoopFrame<AnyHit> frame;
  frame.scene = scene;
  Bvh2Stack stack;
  Bvh2Traversal<AnyHit> walk;
  walk.start(*scene.root, rays[i], stack);
  walk.template run<false>(frame, stack);
  if constexpr (AnyHit) {
    occluded[i] = walk.occluded() ? 1 : 0;
  } else {
    const Hit h = walk.closestHit(frame);
    hits[i] = h.valid() ? InstanceHit{h.t, h.u, h.v, h.tri, frame.prim} : InstanceHit{0.0f, 0.0f, 0.0f, kNoHit, kNoHit};
  }
}

}  // namespace

void launchInstanceBoxes(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* boxes,
                         cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  instanceBoxesKernel<<<gridFor(count, block), block, 0, stream>>>(instances, views, count, boxes);
  CUDA_CHECK_LAUNCH("instanceBoxesKernel");
}

void launchTlasRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                     const uint32_t* triIndex, const Aabb* instanceBoxes, uint32_t* counters, RootInfo* root,
                     cudaStream_t stream) {
  if (leafCount == 0) return;
  const unsigned block = 128;
  tlasRefitKernel<<<gridFor(leafCount, block), block, 0, stream>>>(nodes, nodeParent, leaves, leafCount, triIndex,
                                                                   instanceBoxes, counters, root);
  CUDA_CHECK_LAUNCH("tlasRefitKernel");
}

uint64_t prepareBlockRefits() {
  int device = 0, optIn = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  CUDA_CHECK(cudaDeviceGetAttribute(&optIn, cudaDevAttrMaxSharedMemoryPerBlockOptin, device));
  CUDA_CHECK(cudaFuncSetAttribute(poseBlasBlockKernel, cudaFuncAttributeMaxDynamicSharedMemorySize, optIn));
  CUDA_CHECK(cudaFuncSetAttribute(tlasBlockKernel, cudaFuncAttributeMaxDynamicSharedMemorySize, optIn));
  return uint64_t(optIn);
}

void launchPoseBlasBlocks(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                          uint32_t interiorCount, const uint32_t* slotVertices, uint32_t slots, const float* positions,
                          WoopTriangle* woop, RootInfo* roots, uint32_t poseCount, const BatchStrides& batch,
                          cudaStream_t stream) {
  if (poseCount == 0) return;
  poseBlasBlockKernel<<<poseCount, kBlockThreads, blockRefitBytes(interiorCount), stream>>>(
      nodes, nodeParent, leaves, leafCount, interiorCount, slotVertices, slots, positions, woop, roots, batch);
  CUDA_CHECK_LAUNCH("poseBlasBlockKernel");
}

void launchTlasBlock(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* instanceBoxes,
                     GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                     uint32_t interiorCount, const uint32_t* triIndex, RootInfo* root, cudaStream_t stream) {
  if (count == 0) return;
  tlasBlockKernel<<<1, kTlasBlockThreads, blockRefitBytes(interiorCount), stream>>>(
      instances, views, count, instanceBoxes, nodes, nodeParent, leaves, leafCount, interiorCount, triIndex, root);
  CUDA_CHECK_LAUNCH("tlasBlockKernel");
}

void launchTwoLevelTrace(const TlasScene& scene, const Ray* rays, uint32_t count, InstanceHit* hits, uint8_t* occluded,
                         cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  if (occluded)
    twoLevelTraceKernel<true><<<gridFor(count, block), block, 0, stream>>>(scene, rays, count, hits, occluded);
  else
    twoLevelTraceKernel<false><<<gridFor(count, block), block, 0, stream>>>(scene, rays, count, hits, occluded);
  CUDA_CHECK_LAUNCH("twoLevelTraceKernel");
}

}  // namespace tsah::cuda::detail
