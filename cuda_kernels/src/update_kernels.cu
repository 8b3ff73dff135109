// The per-frame update of an uploaded tree: vertex interpolation, bottom-up refit, Woop triangles.
// Compiled with -fmad=false (see CMakeLists.txt) so every result is bit-identical to the CPU path.
#include <cuda/atomic>

#include <vector>

#include "kernels.hpp"
#include "launch.hpp"
#include "triangle_boxes.cuh"

namespace tsah::cuda::detail {

namespace {

__global__ void interpolateFrameKernel(const float* __restrict__ keyframes, const uint32_t* __restrict__ movingIds,
                                       FrameParams p, float* __restrict__ out, std::size_t count) {
  const float* a = keyframes + p.a;
  const float* b = keyframes + p.b;
  // Same operations and rounding as anim::Animation::positionsAt: beta * a + alpha * b. Scalar
  // accesses: a keyframe starts wherever movingCount * 3 floats put it, not on a 16-byte boundary.
  // count = 3 * movingCount; coordinate i belongs to moving vertex i / 3, written at its own vertex.
  const std::size_t stride = std::size_t(gridDim.x) * blockDim.x;
  const float beta = 1.0f - p.alpha;
  for (std::size_t i = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x; i < count; i += stride) {
    const std::size_t dst = movingIds ? 3 * std::size_t(__ldg(movingIds + i / 3)) + i % 3 : i;
    // alpha == 0: positionsAt copies the keyframe (1 * x + 0 * y would turn -0 into +0).
    out[dst] = p.alpha == 0.0f ? __ldg(a + i) : __fadd_rn(__fmul_rn(beta, __ldg(a + i)), __fmul_rn(p.alpha, __ldg(b + i)));
  }
}

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

__global__ void refitKernel(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                            const LeafRecord* __restrict__ leaves, uint32_t leafCount,
                            const uint32_t* __restrict__ slotVertices,
                            const float* __restrict__ positions, uint32_t* __restrict__ counters,
                            RootInfo* __restrict__ root) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= leafCount) return;
  const LeafRecord leaf = leaves[i];
  Aabb box = leafBox(leaf.first, leaf.count, slotVertices, positions);
  uint32_t slot = leaf.parentSlot;
  // Walk up: the second thread to arrive at a node has both child boxes and carries on.
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

// One thread per slot. The rows go out through shared memory, so that each store instruction of a
// warp writes 512 contiguous bytes (a thread's three 16-byte rows, stored directly, left each
// instruction a third of every sector it touched).
constexpr uint32_t kWoopBlock = 128;
template <class VertexIds>
__global__ void __launch_bounds__(kWoopBlock) woopKernel(VertexIds ids, uint32_t slots,
                                                         const float* __restrict__ positions,
                                                         WoopTriangle* __restrict__ woop) {
  __shared__ float4 rows[3 * kWoopBlock];
  const uint32_t first = blockIdx.x * kWoopBlock, s = first + threadIdx.x;
  if (s < slots) {
    const uint32_t* tri = ids(s);
    const WoopTriangle w = makeWoopTriangle(loadVertex(positions, __ldg(tri)), loadVertex(positions, __ldg(tri + 1)),
                                            loadVertex(positions, __ldg(tri + 2)));
    rows[3 * threadIdx.x] = make_float4(w.r0.x, w.r0.y, w.r0.z, w.r0.w);
    rows[3 * threadIdx.x + 1] = make_float4(w.r1.x, w.r1.y, w.r1.z, w.r1.w);
    rows[3 * threadIdx.x + 2] = make_float4(w.r2.x, w.r2.y, w.r2.z, w.r2.w);
  }
  __syncthreads();
  const uint32_t rowCount = 3 * (slots - first < kWoopBlock ? slots - first : kWoopBlock);
  float4* out = reinterpret_cast<float4*>(woop + first);
  for (uint32_t r = threadIdx.x; r < rowCount; r += kWoopBlock) out[r] = rows[r];
}

template <class VertexIds>
void launchWoopKernel(VertexIds ids, uint32_t slots, const float* positions, WoopTriangle* woop, cudaStream_t stream) {
  if (slots == 0) return;
  woopKernel<<<gridFor(slots, kWoopBlock), kWoopBlock, 0, stream>>>(ids, slots, positions, woop);
  CUDA_CHECK_LAUNCH("woopKernel");
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
  const std::vector<InterpolationNode> found = findInterpolationNodes(graph);
  return found.empty() ? InterpolationNode{} : found.front();
}

std::vector<InterpolationNode> findInterpolationNodes(cudaGraph_t graph) {
  std::vector<InterpolationNode> all;
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
    if (found.launch.func == reinterpret_cast<void*>(&interpolateFrameKernel)) all.push_back(found);
  }
  return all;
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
  if (leafCount == 0) return;
  const uint32_t block = 128;
  refitKernel<<<gridFor(leafCount, block), block, 0, stream>>>(nodes, nodeParent, leaves, leafCount,
                                                               slotVertices, positions, counters, root);
  CUDA_CHECK_LAUNCH("refitKernel");
}

void launchWoop(const uint32_t* triIndex, uint32_t slots, const uint32_t* indices, const float* positions,
                WoopTriangle* woop, cudaStream_t stream) {
  launchWoopKernel(GatheredIds{triIndex, indices}, slots, positions, woop, stream);
}

void launchSlotWoop(const uint32_t* slotVertices, uint32_t slots, const float* positions, WoopTriangle* woop,
                    cudaStream_t stream) {
  launchWoopKernel(SlotOrderedIds{slotVertices}, slots, positions, woop, stream);
}

void launchMovingSlotWoop(const uint32_t* movingSlots, uint32_t count, const uint32_t* slotVertices,
                          const float* positions, WoopTriangle* woop, cudaStream_t stream) {
  if (count == 0) return;
  const uint32_t block = 128;
  movingSlotWoopKernel<<<gridFor(count, block), block, 0, stream>>>(movingSlots, count, slotVertices, positions, woop);
  CUDA_CHECK_LAUNCH("movingSlotWoopKernel");
}

}  // namespace tsah::cuda::detail
