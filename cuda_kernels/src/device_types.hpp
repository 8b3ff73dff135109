#pragma once
// Plain data shared by the host code and the kernels of the GPU runtime (no CUDA syntax here, so
// the C++ compiler reads it too).
#include <cstdint>
#include <type_traits>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/cwbvh_layout.hpp"
#include "tsah/layout/gpu_layout.hpp"
#include "tsah/layout/refit_parts.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah::cuda::detail {

inline constexpr uint32_t kNoParent = 0xffffffffu;

// The root of the tree being traced, kept in device memory because the refit and the rebuilds
// compute it on the device (no round trip to the host between update and trace).
struct alignas(16) RootInfo {
  Aabb box;                    // the whole tree
  int32_t ref = makeLeafRef(0);  // node 0.. or a leaf reference (the whole tree is one leaf)
  uint32_t count = 0;          // triangles of the root when it is a leaf, else 0
  uint32_t interiorCount = 0;  // reachable interior nodes (rebuilt trees)
  uint32_t depth = 0;          // depth of the deepest leaf (rebuilt trees)
};
static_assert(sizeof(RootInfo) == 48 && std::is_trivially_copyable_v<RootInfo>);

// Everything a traversal reads; device pointers only, passed to kernels by value.
struct TraceScene {
  const GpuBvhNode* nodes = nullptr;
  const WoopTriangle* woop = nullptr;   // per slot
  const uint32_t* triIndex = nullptr;   // slot -> triangle id
  const uint32_t* indices = nullptr;    // 3 per triangle id
  const float* positions = nullptr;     // xyz per vertex, this frame
  const RootInfo* root = nullptr;
  // The compressed 8-wide layout (GpuRuntime::Config::layout == cwbvh): when set, the traversal
  // runs over these nodes, and woop / triIndex above are per slot of that layout.
  const CwbvhNode* cwbvhNodes = nullptr;
  int32_t cwbvhRootRef = 0;
  uint32_t cwbvhRootCount = 0;
};

// A leaf of an uploaded tree as the refit sees it: where its box goes (interior node * 2 + side,
// kNoParent for a tree that is one leaf) and its triangle slots.
struct LeafRecord {
  uint32_t parentSlot;
  uint32_t first;
  uint32_t count;
};

// Which keyframes the interpolation blends: a kernel argument, which the runtime sets in its
// captured graphs before each launch (setInterpolationParams), so one graph serves every frame.
// Offsets are in floats; keyA and keyB are the keyframes' indices (the keyed pose update's boxes).
// held: a two-level pose whose local time is the last update's; the pose kernels skip it (its
// positions, boxes and Woop triangles are already this frame's).
struct alignas(16) FrameParams {
  uint64_t a = 0, b = 0;
  float alpha = 0.0f;
  uint32_t keyA = 0, keyB = 0;
  uint32_t held = 0;
};

// The frame blending keyframe k towards k + 1 by alpha (anim::keyframeBlend) of an animation with
// movingVertices moving vertices (alpha 0 reads keyframe k alone).
inline FrameParams blendFrame(uint32_t k, float alpha, uint32_t movingVertices) {
  const uint64_t perFrame = uint64_t(movingVertices) * 3;
  FrameParams frame;
  frame.keyA = k;
  frame.keyB = alpha == 0.0f ? k : k + 1;
  frame.a = frame.keyA * perFrame;
  frame.b = frame.keyB * perFrame;
  frame.alpha = alpha;
  return frame;
}

// Trees of one topology updated together by one launch per kernel (the two-level runtime's poses of
// one source, each with its own positions, boxes and Woop triangles): member b of the batch reads and
// writes its arrays at b times these strides (in elements); it has its own root (root + b) and, in
// the interpolation, its own frame (frames[b]). A single tree is a batch of one with zero strides.
struct BatchStrides {
  uint64_t positions = 0, nodes = 0, woop = 0, counters = 0;
};

// A tree split for block refits (tsah::RefitParts) on the device: parts[subtreeCount] is the top
// when hasTop.
struct RefitPartsView {
  const RefitPart* parts = nullptr;
  const uint32_t* parentSlot = nullptr;
  const uint32_t* globalNode = nullptr;
  const RefitPartItem* items = nullptr;
  uint32_t subtreeCount = 0;
  uint32_t hasTop = 0;
};

// Shared-memory bytes of a part's block refit (refit_walk.cuh's partRefit) of nodeCount local
// nodes: an arrival counter, the parent's local slot, the node's index in the tree and its 12 box
// floats per node; with slots, 6 box floats per triangle slot of the part (the pose kernel's
// triangle boxes).
TSAH_HD constexpr uint32_t partWalkWords(uint32_t nodeCount) { return 15u * nodeCount; }
constexpr uint64_t partRefitBytes(uint32_t nodeCount, uint32_t slotCount = 0) {
  return (uint64_t(partWalkWords(nodeCount)) + uint64_t(slotCount) * 6u) * 4u;
}

struct TraceLaunch {
  bool persistent = true;   // Aila-Laine persistent warps fetching rays from a global counter
  uint32_t blockSize = 128;
  uint32_t blocks = 0;      // persistent: resident blocks (0: from the occupancy calculator)
};

}  // namespace tsah::cuda::detail
