// The per-frame update of an uploaded tree: vertex interpolation, bottom-up refit, Woop triangles.
// Compiled with -fmad=false (see CMakeLists.txt) so every result is bit-identical to the CPU path.
#include <algorithm>
#include <vector>

#include "kernels.hpp"
#include "launch.hpp"
#include "refit_walk.cuh"
#include "triangle_boxes.cuh"
#include "woop_block.cuh"

namespace tsah::cuda::detail {

namespace {

// Same operations and rounding as anim::Animation::positionsAt: beta * a + alpha * b. Scalar
// accesses: a keyframe starts wherever movingCount * 3 floats put it, not on a 16-byte boundary.
// count = 3 * movingCount; coordinate i belongs to moving vertex i / 3, written at its own vertex.
__device__ __forceinline__ void interpolateCoordinates(const float* __restrict__ keyframes,
                                                       const uint32_t* __restrict__ movingIds, const FrameParams& p,
                                                       float* __restrict__ out, std::size_t count) {
  const float* a = keyframes + p.a;
  const float* b = keyframes + p.b;
  const std::size_t stride = std::size_t(gridDim.x) * blockDim.x;
  const float beta = 1.0f - p.alpha;
  for (std::size_t i = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x; i < count; i += stride) {
    const std::size_t dst = movingIds ? 3 * std::size_t(__ldg(movingIds + i / 3)) + i % 3 : i;
    // alpha == 0: positionsAt copies the keyframe (1 * x + 0 * y would turn -0 into +0).
    out[dst] = p.alpha == 0.0f ? __ldg(a + i) : __fadd_rn(__fmul_rn(beta, __ldg(a + i)), __fmul_rn(p.alpha, __ldg(b + i)));
  }
}

__global__ void interpolateFrameKernel(const float* __restrict__ keyframes, const uint32_t* __restrict__ movingIds,
                                       FrameParams p, float* __restrict__ out, std::size_t count) {
  interpolateCoordinates(keyframes, movingIds, p, out, count);
}

// A batch: member blockIdx.y blends its own frame into its own positions (none for a held frame).
__global__ void interpolateBatchKernel(const float* __restrict__ keyframes, const uint32_t* __restrict__ movingIds,
                                       const FrameParams* __restrict__ frames, float* __restrict__ out,
                                       std::size_t count, uint64_t outStride) {
  const FrameParams frame = frames[blockIdx.y];
  if (frame.held) return;
  interpolateCoordinates(keyframes, movingIds, frame, out + blockIdx.y * outStride, count);
}

__global__ void refitKernel(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                            const LeafRecord* __restrict__ leaves, uint32_t leafCount,
                            const uint32_t* __restrict__ slotVertices, const float* __restrict__ positions,
                            uint32_t* __restrict__ counters, RootInfo* __restrict__ root, BatchStrides batch,
                            const FrameParams* __restrict__ frames) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= leafCount) return;
  const uint32_t b = blockIdx.y;
  if (frames != nullptr && frames[b].held) return;
  const LeafRecord leaf = leaves[i];
  const Aabb box = leafBox(leaf.first, leaf.count, slotVertices, positions + b * batch.positions);
  refitUpwards(nodes + b * batch.nodes, nodeParent, leaf.parentSlot, box, counters + b * batch.counters, root + b);
}

// Where the Woop pass finds the vertex ids of slot s: in slot order (the refits' slotVertices,
// streamed) or through the slot's triangle id (the rebuilds, whose slot order changes every frame).
struct SlotOrderedIds {
  const uint32_t* ids;
  __device__ const uint32_t* operator()(uint32_t s) const { return ids + 3 * std::size_t(s); }
};
struct GatheredIds {
  const uint32_t* triIndex;
  const uint32_t* indices;
  __device__ const uint32_t* operator()(uint32_t s) const { return indices + 3 * std::size_t(__ldg(triIndex + s)); }
};

// One thread per slot (woop_block.cuh).
template <class VertexIds>
__global__ void __launch_bounds__(kWoopBlock) woopKernel(VertexIds ids, uint32_t slots,
                                                         const float* __restrict__ positions,
                                                         WoopTriangle* __restrict__ woop, BatchStrides batch,
                                                         const FrameParams* __restrict__ frames) {
  if (frames != nullptr && frames[blockIdx.y].held) return;  // the whole block: no barrier is left waiting
  positions += blockIdx.y * batch.positions;
  woop += blockIdx.y * batch.woop;
  woopBlock(blockIdx.x * kWoopBlock, slots, [&](uint32_t s, Vec3* v) {
    const uint32_t* tri = ids(s);
    for (int k = 0; k < 3; ++k) v[k] = loadVertex(positions, __ldg(tri + k));
  }, woop);
}

template <class VertexIds>
void launchWoopKernel(VertexIds ids, uint32_t slots, const float* positions, WoopTriangle* woop, uint32_t batchCount,
                      const BatchStrides& batch, const FrameParams* frames, cudaStream_t stream) {
  if (slots == 0) return;
  forEachBatchChunk(batchCount, [&](uint32_t first, uint32_t count) {
    const dim3 grid(gridFor(slots, kWoopBlock), count);
    woopKernel<<<grid, kWoopBlock, 0, stream>>>(ids, slots, positions + first * batch.positions,
                                                woop + first * batch.woop, batch, frames ? frames + first : nullptr);
    CUDA_CHECK_LAUNCH("woopKernel");
  });
}

// One thread per listed slot: a static scene's moving triangles are few and scattered, so each
// thread stores its own triangle (the others stay as the last full update left them).
__global__ void movingSlotWoopKernel(const uint32_t* __restrict__ movingSlots, uint32_t count,
                                     const uint32_t* __restrict__ slotVertices, const float* __restrict__ positions,
                                     WoopTriangle* __restrict__ woop) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const uint32_t s = __ldg(movingSlots + i);
  const uint32_t* tri = slotVertices + 3 * std::size_t(s);
  woop[s] = makeWoopTriangle(loadVertex(positions, __ldg(tri)), loadVertex(positions, __ldg(tri + 1)),
                             loadVertex(positions, __ldg(tri + 2)));
}

}  // namespace

void launchInterpolateFrame(const float* keyframes, const uint32_t* movingIds, const FrameParams& params, float* out,
                            uint32_t movingCount, cudaStream_t stream) {
  const std::size_t count = std::size_t(movingCount) * 3;
  if (count == 0) return;
  const uint32_t block = 256;
  interpolateFrameKernel<<<gridFor(count, block), block, 0, stream>>>(keyframes, movingIds, params, out, count);
  CUDA_CHECK_LAUNCH("interpolateFrameKernel");
}

InterpolationNode findInterpolationNode(cudaGraph_t graph) {
  std::size_t count = 0;
  CUDA_CHECK(cudaGraphGetNodes(graph, nullptr, &count));
  std::vector<cudaGraphNode_t> nodes(count);
  CUDA_CHECK(cudaGraphGetNodes(graph, nodes.data(), &count));
  for (cudaGraphNode_t node : nodes) {
    cudaGraphNodeType type;
    CUDA_CHECK(cudaGraphNodeGetType(node, &type));
    if (type != cudaGraphNodeTypeKernel) continue;
    InterpolationNode found{node, {}};
    CUDA_CHECK(cudaGraphKernelNodeGetParams(node, &found.launch));
    if (found.launch.func == reinterpret_cast<void*>(&interpolateFrameKernel)) return found;
  }
  return {};
}

void setInterpolationParams(cudaGraphExec_t exec, const InterpolationNode& node, const FrameParams& params) {
  cudaKernelNodeParams p = node.launch;
  // The captured arguments (keyframes, movingIds, out, count) stay; only the frame changes.
  void* args[5] = {p.kernelParams[0], p.kernelParams[1], const_cast<FrameParams*>(&params), p.kernelParams[3],
                   p.kernelParams[4]};
  p.kernelParams = args;
  p.extra = nullptr;
  CUDA_CHECK(cudaGraphExecKernelNodeSetParams(exec, node.node, &p));
}

void launchRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                 const uint32_t* slotVertices, const float* positions, uint32_t* counters, RootInfo* root,
                 cudaStream_t stream) {
  launchBatchRefit(nodes, nodeParent, leaves, leafCount, slotVertices, positions, counters, root, 1, BatchStrides{},
                   stream);
}

void launchBatchRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                      const uint32_t* slotVertices, const float* positions, uint32_t* counters, RootInfo* roots,
                      uint32_t batchCount, const BatchStrides& batch, cudaStream_t stream,
                      const FrameParams* frames) {
  if (leafCount == 0) return;
  const uint32_t block = 128;
  forEachBatchChunk(batchCount, [&](uint32_t first, uint32_t count) {
    const dim3 grid(gridFor(leafCount, block), count);
    refitKernel<<<grid, block, 0, stream>>>(nodes + first * batch.nodes, nodeParent, leaves, leafCount, slotVertices,
                                            positions + first * batch.positions, counters + first * batch.counters,
                                            roots + first, batch, frames ? frames + first : nullptr);
    CUDA_CHECK_LAUNCH("refitKernel");
  });
}

void launchBatchInterpolate(const float* keyframes, const uint32_t* movingIds, const FrameParams* frames, float* out,
                            uint32_t movingCount, uint32_t batchCount, uint64_t outStride, cudaStream_t stream) {
  const std::size_t count = std::size_t(movingCount) * 3;
  if (count == 0) return;
  const uint32_t block = 256;
  forEachBatchChunk(batchCount, [&](uint32_t first, uint32_t rows) {
    const dim3 grid(gridFor(count, block), rows);
    interpolateBatchKernel<<<grid, block, 0, stream>>>(keyframes, movingIds, frames + first, out + first * outStride,
                                                       count, outStride);
    CUDA_CHECK_LAUNCH("interpolateBatchKernel");
  });
}

void launchWoop(const uint32_t* triIndex, uint32_t slots, const uint32_t* indices, const float* positions,
                WoopTriangle* woop, cudaStream_t stream) {
  launchWoopKernel(GatheredIds{triIndex, indices}, slots, positions, woop, 1, BatchStrides{}, nullptr, stream);
}

void launchSlotWoop(const uint32_t* slotVertices, uint32_t slots, const float* positions, WoopTriangle* woop,
                    cudaStream_t stream) {
  launchWoopKernel(SlotOrderedIds{slotVertices}, slots, positions, woop, 1, BatchStrides{}, nullptr, stream);
}

void launchBatchSlotWoop(const uint32_t* slotVertices, uint32_t slots, const float* positions, WoopTriangle* woop,
                         uint32_t batchCount, const BatchStrides& batch, cudaStream_t stream,
                         const FrameParams* frames) {
  launchWoopKernel(SlotOrderedIds{slotVertices}, slots, positions, woop, batchCount, batch, frames, stream);
}

void launchMovingSlotWoop(const uint32_t* movingSlots, uint32_t count, const uint32_t* slotVertices,
                          const float* positions, WoopTriangle* woop, cudaStream_t stream) {
  if (count == 0) return;
  const uint32_t block = 128;
  movingSlotWoopKernel<<<gridFor(count, block), block, 0, stream>>>(movingSlots, count, slotVertices, positions, woop);
  CUDA_CHECK_LAUNCH("movingSlotWoopKernel");
}

}  // namespace tsah::cuda::detail
