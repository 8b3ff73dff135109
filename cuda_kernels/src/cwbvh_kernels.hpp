#pragma once
// Launchers of the compressed 8-wide BVH kernels (cwbvh.cu; layout in tsah/cwbvh_layout.hpp).
// Each checks its launch and throws CudaError; none synchronizes.
#include <cuda_runtime_api.h>

#include <cstdint>

#include "device_types.hpp"
#include "tsah/cwbvh_build.hpp"

namespace tsah::cuda::detail {

// Per frame: exact leaf boxes from the triangles, bottom-up (atomic arrival counter per node, zero
// on entry; the last child to arrive finishes its node's union), root->box; then every node
// re-quantized with cwbvhQuantize in parallel. exact: nodeCount * 8 scratch boxes. Results equal
// tsah::refitCwbvh.
void launchCwbvhRefit(CwbvhNode* nodes, uint32_t nodeCount, Aabb* exact, const uint32_t* parentSlot,
                      const CwbvhLeaf* leaves, uint32_t leafCount, const uint32_t* triIndex, const uint32_t* indices,
                      const float* positions, uint32_t* counters, RootInfo* root, cudaStream_t stream);

// The traversal's view of a scene in the compressed layout (rootBox is read on the device from
// scene.root).
inline CwbvhView cwbvhView(const TraceScene& scene) {
  CwbvhView view;
  view.nodes = scene.cwbvhNodes;
  view.woop = scene.woop;
  view.triIndex = scene.triIndex;
  view.indices = scene.indices;
  view.positions = scene.positions;
  view.rootRef = scene.cwbvhRootRef;
  view.rootCount = scene.cwbvhRootCount;
  return view;
}

// cwbvhClosestHit into hits (hits != nullptr) or cwbvhAnyHit into occluded: one thread per ray, or
// with launch.persistent resident threads taking rays from rayCounter (one device word, zero on
// entry) as theirs finish.
void launchCwbvhTrace(const TraceScene& scene, const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded,
                      uint32_t* rayCounter, const TraceLaunch& launch, cudaStream_t stream);

}  // namespace tsah::cuda::detail
