// The kernels behind GpuRuntime's device-array entry points. The traversal reads the caller's
// (n, 3) arrays directly instead of packing them into Ray records first: 24 bytes per ray read
// (plus 4 for each per-ray limit), where a packing kernel would read them, write a 32-byte Ray and
// the traversal read that again (88 bytes per ray, and a 32-byte-per-ray scratch buffer: 320 MB for
// 10M rays).
#include <cmath>
#include <vector>

#include "bvh2_traversal.cuh"
#include "cwbvh_kernels.hpp"
#include "device_arrays.hpp"
#include "launch.hpp"
#include "ray_arrays.cuh"
#include "tsah/base/coordinates.hpp"
#include "tsah/layout/cwbvh_layout.hpp"

namespace tsah::cuda::detail {

namespace {

__global__ void firstBadVertexKernel(const float* __restrict__ positions, std::size_t coordinates,
                                     uint32_t* __restrict__ firstBad) {
  const std::size_t stride = std::size_t(gridDim.x) * blockDim.x;
  for (std::size_t i = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x; i < coordinates; i += stride)
    if (!(fabsf(__ldg(positions + i)) <= kMaxCoordinate)) atomicMin(firstBad, uint32_t(i / 3));  // NaN fails too
}

// report[0]: the first bad vertex (launchFirstBadVertex) or kNoBadVertex. Good: target = source;
// bad: target untouched, report[1..3] = the bits of the bad vertex's coordinates (for the message,
// read later when the caller's buffer may have changed).
__global__ void copyIfValidKernel(const float* __restrict__ source, float* __restrict__ target,
                                  std::size_t coordinates, uint32_t* __restrict__ report) {
  const uint32_t bad = *report;
  const std::size_t first = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (bad != kNoBadVertex) {
    if (first < 3) report[1 + first] = __float_as_uint(source[3 * std::size_t(bad) + first]);
    return;
  }
  const std::size_t stride = std::size_t(gridDim.x) * blockDim.x;
  for (std::size_t i = first; i < coordinates; i += stride) target[i] = __ldg(source + i);
}

__device__ __forceinline__ void storeHit(const ArrayHits& out, uint32_t i, Hit h) {
  if (!h.valid()) h = Hit{INFINITY, 0.0f, 0.0f, kNoHit};
  if (out.t) out.t[i] = h.t;
  if (out.u) out.u[i] = h.u;
  if (out.v) out.v[i] = h.v;
  if (out.triangle) out.triangle[i] = h.tri;
}

// Wide: the compressed 8-wide layout (scene.cwbvhNodes), else the binary one; the traversals are
// the runtime's own (bvh2_traversal.cuh, tsah/layout/cwbvh_layout.hpp).
template <bool AnyHit, bool Wide>
__global__ void __launch_bounds__(128) arrayTraceKernel(TraceScene scene, CwbvhView view, ArrayRays rays,
                                                        ArrayHits hits, uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= rays.count) return;
  const Ray ray = loadRay(rays, i);
  Hit h;
  if constexpr (Wide) {
    view.rootBox = scene.root->box;
    if constexpr (AnyHit)
      h.tri = cwbvhAnyHit(view, ray) ? 0u : kNoHit;
    else
      h = cwbvhClosestHit(view, ray);
  } else {
    const RootInfo root = *scene.root;
    if constexpr (AnyHit)
      h.tri = bvh2AnyHit(scene, root, ray) ? 0u : kNoHit;
    else
      h = bvh2ClosestHit(scene, root, ray);
  }
  if constexpr (AnyHit)
    occluded[i] = h.valid() ? 1 : 0;
  else
    storeHit(hits, i, h);
}

template <bool AnyHit, bool Wide>
void launchArrayTyped(const TraceScene& scene, const ArrayRays& rays, const ArrayHits& hits, uint8_t* occluded,
                      cudaStream_t stream) {
  const unsigned block = 128;  // fixed by __launch_bounds__
  arrayTraceKernel<AnyHit, Wide><<<gridFor(rays.count, block), block, 0, stream>>>(
      scene, Wide ? cwbvhView(scene) : CwbvhView{}, rays, hits, occluded);
  CUDA_CHECK_LAUNCH(AnyHit ? "arrayTraceKernel<any hit>" : "arrayTraceKernel<closest hit>");
}

}  // namespace

void launchFirstBadVertex(const float* positions, uint32_t vertexCount, uint32_t* firstBad, cudaStream_t stream) {
  if (vertexCount == 0) return;
  const std::size_t coordinates = std::size_t(vertexCount) * 3;
  const unsigned block = 256;
  const unsigned grid = std::min(gridFor(coordinates, block), 4096u);  // grid-stride beyond ~1M coordinates
  firstBadVertexKernel<<<grid, block, 0, stream>>>(positions, coordinates, firstBad);
  CUDA_CHECK_LAUNCH("firstBadVertexKernel");
}

void launchCopyIfValid(const float* source, float* target, uint32_t vertexCount, uint32_t* report,
                       cudaStream_t stream) {
  if (vertexCount == 0) return;
  const std::size_t coordinates = std::size_t(vertexCount) * 3;
  const unsigned block = 256;
  const unsigned grid = std::min(gridFor(coordinates, block), 4096u);
  copyIfValidKernel<<<grid, block, 0, stream>>>(source, target, coordinates, report);
  CUDA_CHECK_LAUNCH("copyIfValidKernel");
}

SourceNodes findSourceNodes(cudaGraph_t graph) {
  std::size_t count = 0;
  CUDA_CHECK(cudaGraphGetNodes(graph, nullptr, &count));
  std::vector<cudaGraphNode_t> nodes(count);
  CUDA_CHECK(cudaGraphGetNodes(graph, nodes.data(), &count));
  SourceNodes found;
  for (cudaGraphNode_t node : nodes) {
    cudaGraphNodeType type;
    CUDA_CHECK(cudaGraphNodeGetType(node, &type));
    if (type != cudaGraphNodeTypeKernel) continue;
    SourceNodes::Node n{node, {}};
    CUDA_CHECK(cudaGraphKernelNodeGetParams(node, &n.launch));
    if (n.launch.func == reinterpret_cast<void*>(&firstBadVertexKernel)) found.check = n;
    if (n.launch.func == reinterpret_cast<void*>(&copyIfValidKernel)) found.copy = n;
  }
  return found;
}

void setSource(cudaGraphExec_t exec, const SourceNodes& nodes, const float* source) {
  // Argument 0 of both kernels is the source; the others keep their captured values.
  for (const SourceNodes::Node* n : {&nodes.check, &nodes.copy}) {
    if (!n->node) continue;
    cudaKernelNodeParams p = n->launch;
    void* args[4] = {&source, p.kernelParams[1], p.kernelParams[2], n == &nodes.copy ? p.kernelParams[3] : nullptr};
    p.kernelParams = args;
    p.extra = nullptr;
    CUDA_CHECK(cudaGraphExecKernelNodeSetParams(exec, n->node, &p));
  }
}

void launchArrayTrace(const TraceScene& scene, const ArrayRays& rays, const ArrayHits& hits, uint8_t* occluded,
                      cudaStream_t stream) {
  if (rays.count == 0) return;
  const bool wide = scene.cwbvhNodes != nullptr;
  if (occluded && wide)
    launchArrayTyped<true, true>(scene, rays, hits, occluded, stream);
  else if (occluded)
    launchArrayTyped<true, false>(scene, rays, hits, occluded, stream);
  else if (wide)
    launchArrayTyped<false, true>(scene, rays, hits, occluded, stream);
  else
    launchArrayTyped<false, false>(scene, rays, hits, occluded, stream);
}

}  // namespace tsah::cuda::detail
