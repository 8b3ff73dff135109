#pragma once
// Launchers of the compressed 8-wide BVH kernels (cwbvh.cu; layout in tsah/cwbvh_layout.hpp).
// Each checks its launch and throws CudaError; none synchronizes.
#include <cuda_runtime_api.h>

#include <cstdint>
#include <vector>

#include "device_types.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah_cuda/device_buffer.hpp"

namespace tsah::cuda::detail {

// What the per-frame refit of a compressed tree launches: the node groups of tsah::cwbvhLevels (on
// the device, and their starts on the host to size the launches), or the one leaf of a tree
// without nodes. Made once at upload by makeCwbvhRefitPlan.
struct CwbvhRefitPlan {
  DeviceBuffer<uint32_t> levelNodes, levelStarts;  // CwbvhLevels::nodes, ::starts
  std::vector<uint32_t> starts;                    // host copy of CwbvhLevels::starts
  uint32_t firstTopGroup = 0;                      // the groups from here on run in one block
  DeviceBuffer<Aabb> topLeafBoxes;                 // scratch: 8 boxes per node of those groups
  uint32_t rootLeafFirst = 0, rootLeafCount = 0;   // a tree without nodes: its leaf's slots
  // The scratch boxes one tree's refit uses (a batch: that many per member).
  uint64_t topLeafBoxCount() const {
    return starts.empty() ? 0 : uint64_t(starts.back() - starts[firstTopGroup]) * kCwbvhWidth;
  }
};

// The root of `tree` as the device keeps it (box, reference, count, nodes, depth).
RootInfo cwbvhRoot(const CwbvhTree& tree);

// The plan of `tree` (uploads on `stream` and waits for them).
CwbvhRefitPlan makeCwbvhRefitPlan(const CwbvhTree& tree, cudaStream_t stream);

// Per frame: every node's exact child boxes (leaf boxes from the triangles, interior children's
// unions from nodeBoxes) and its re-quantization, group by group bottom-up, 8 lanes per node; the
// node's union into nodeBoxes (nodeCount boxes of scratch) and the root's into root->box. Results
// equal tsah::refitCwbvh. slotVertices: 3 vertex ids per slot (tsah::slotVertexIndices); plan:
// non-const for its scratch boxes.
void launchCwbvhRefit(CwbvhRefitPlan& plan, CwbvhNode* nodes, Aabb* nodeBoxes, const uint32_t* slotVertices,
                      const float* positions, RootInfo* root, cudaStream_t stream);

// launchCwbvhRefit for a batch of trees of one topology (the two-level runtime's poses): member b
// refits nodes + b * batch.nodes (and as many node boxes) from positions + b * batch.positions into
// roots[b]; topLeafBoxes: plan.topLeafBoxCount() scratch boxes per member. A member whose frame is
// held (FrameParams::held) is left as it is (frames null: every member is refitted).
void launchBatchCwbvhRefit(const CwbvhRefitPlan& plan, CwbvhNode* nodes, Aabb* nodeBoxes, Aabb* topLeafBoxes,
                           const uint32_t* slotVertices, const float* positions, RootInfo* roots,
                           uint32_t batchCount, const BatchStrides& batch, const FrameParams* frames,
                           cudaStream_t stream);

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
