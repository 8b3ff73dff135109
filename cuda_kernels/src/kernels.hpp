#pragma once
// Host-side launchers of the runtime's kernels (defined in the .cu files). Every launcher checks the
// launch and throws CudaError; none synchronizes.
#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "device_types.hpp"

namespace tsah::cuda::detail {

// The triangles of each vertex of a mesh (3 vertex ids per triangle), in increasing order: the order
// the renderers sum face normals in. CSR: vertex v's triangles are triangles[offsets[v] ..
// offsets[v + 1]) (a triangle naming v twice is listed twice). Host code (gpu_runtime.cpp).
struct VertexTriangles {
  std::vector<uint32_t> offsets, triangles;
};
VertexTriangles vertexTriangles(std::span<const uint32_t> indices, uint32_t vertexCount);

// The moving vertices of the frame: for m < movingCount and c < 3, with i = 3m + c,
// out[3 * v + c] = (1 - alpha) * a[i] + alpha * b[i], a = keyframes + params.a, b = keyframes + params.b,
// v = movingIds[m] (or m when movingIds is null: every vertex moves); rounded exactly as
// anim::Animation::positionsAt does (alpha == 0 copies a). Static vertices are not touched.
void launchInterpolateFrame(const float* keyframes, const uint32_t* movingIds, const FrameParams& params, float* out,
                            uint32_t movingCount, cudaStream_t stream);

// The interpolation's kernel node in a graph captured around launchInterpolateFrame (node null
// when there is none: no moving vertex) with its captured launch, and the update of its frame
// before a launch of the graph. (Copying the parameters from pinned host memory inside the graph
// cost a transfer per frame.) The launch's argument pointers live as long as the graph.
struct InterpolationNode {
  cudaGraphNode_t node = nullptr;
  cudaKernelNodeParams launch{};
};
InterpolationNode findInterpolationNode(cudaGraph_t graph);
void setInterpolationParams(cudaGraphExec_t exec, const InterpolationNode& node, const FrameParams& params);

// Bottom-up refit of an uploaded tree: one thread per leaf record, atomic counters per interior node
// (must be zero on entry); writes every child box, and root->box. slotVertices: 3 vertex ids per
// slot (tsah::slotVertexIndices).
void launchRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                 const uint32_t* slotVertices, const float* positions, uint32_t* counters, RootInfo* root,
                 cudaStream_t stream);

// The same three steps for a batch of trees of one topology (BatchStrides): member b interpolates
// frames[b] into out + b * outStride, refits its nodes into roots[b], recomputes its Woop triangles.
// Counters of every member zero on entry, as for launchRefit. A member whose frame is held
// (FrameParams::held) is left as it is by all three; the refit and the Woop pass read that from
// `frames` when given (null: every member is updated).
void launchBatchInterpolate(const float* keyframes, const uint32_t* movingIds, const FrameParams* frames, float* out,
                            uint32_t movingCount, uint32_t batchCount, uint64_t outStride, cudaStream_t stream);
void launchBatchRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                      const uint32_t* slotVertices, const float* positions, uint32_t* counters, RootInfo* roots,
                      uint32_t batchCount, const BatchStrides& batch, cudaStream_t stream,
                      const FrameParams* frames = nullptr);
void launchBatchSlotWoop(const uint32_t* slotVertices, uint32_t slots, const float* positions, WoopTriangle* woop,
                         uint32_t batchCount, const BatchStrides& batch, cudaStream_t stream,
                         const FrameParams* frames = nullptr);

// Woop triangle of every slot, the vertex ids found through the slot's triangle id (the rebuilds)
// or in slot order (launchSlotWoop: the refits' slotVertices).
void launchWoop(const uint32_t* triIndex, uint32_t slots, const uint32_t* indices, const float* positions,
                WoopTriangle* woop, cudaStream_t stream);
void launchSlotWoop(const uint32_t* slotVertices, uint32_t slots, const float* positions, WoopTriangle* woop,
                    cudaStream_t stream);
// The Woop triangles of the slots listed in movingSlots only (the others keep theirs): the update of
// a tree whose static subtrees were refitted before (moving_parts.hpp).
void launchMovingSlotWoop(const uint32_t* movingSlots, uint32_t count, const uint32_t* slotVertices,
                          const float* positions, WoopTriangle* woop, cudaStream_t stream);

// Traversal of `count` rays: closest hit into hits (when hits != nullptr) or any hit into
// occluded (1 = something hit). rayCounter: one device word, zero on entry (persistent launch).
void launchTrace(const TraceScene& scene, const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded,
                 uint32_t* rayCounter, const TraceLaunch& launch, cudaStream_t stream);

// Resident blocks per multiprocessor of the persistent traversal kernel.
int traceBlocksPerMultiprocessor(bool anyHit, uint32_t blockSize);

}  // namespace tsah::cuda::detail
