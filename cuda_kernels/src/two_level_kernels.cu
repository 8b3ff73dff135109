// The two-level runtime's kernels: instance world boxes, the TLAS refit over them, and the trace
// of ray arrays through instances (two_level_traversal.cuh).
// Compiled with -fmad=false (see CMakeLists.txt): boxes and hits round as on the CPU.
#include "launch.hpp"
#include "refit_walk.cuh"
#include "triangle_boxes.cuh"
#include "two_level_traversal.cuh"
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

template <bool AnyHit>
__global__ void __launch_bounds__(128) twoLevelTraceKernel(TlasScene scene, const Ray* __restrict__ rays,
                                                           uint32_t count, InstanceHit* __restrict__ hits,
                                                           uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  if constexpr (AnyHit)
    occluded[i] = twoLevelAnyHit(scene, rays[i]) ? 1 : 0;
  else
    hits[i] = twoLevelClosestHit(scene, rays[i]);
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
