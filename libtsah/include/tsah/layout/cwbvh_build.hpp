#pragma once
// Builds the compressed 8-wide layout (cwbvh_layout.hpp) from a WideBvh of width <= 8, and the
// host refit + re-quantization of it (the reference the GPU runtime's per-frame kernel matches).
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tsah/layout/cwbvh_layout.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/wide_bvh.hpp"

namespace tsah {

// A leaf child of the compressed tree as the refit sees it: where its box goes (node * 8 + slot,
// kCwbvhNoParent for a tree that is one leaf) and its triangle slots.
inline constexpr uint32_t kCwbvhNoParent = 0xffffffffu;
struct CwbvhLeaf {
  uint32_t nodeSlot;
  uint32_t first;
  uint32_t count;
};

struct CwbvhTree {
  std::vector<CwbvhNode> nodes;        // node 0 is the root; children after their parent (breadth-first)
  std::vector<uint32_t> triIndex;      // slot -> triangle id (a node's leaf triangles are contiguous)
  std::vector<uint32_t> parentSlot;    // per node: parent * 8 + slot, kCwbvhNoParent for the root
  std::vector<CwbvhLeaf> leaves;
  std::vector<Aabb> exactBoxes;        // nodes * 8 (node * 8 + slot): the float boxes last quantized
  int32_t rootRef = 0;                 // node 0, or a leaf reference when the tree is one leaf
  uint32_t rootCount = 0;
  Aabb rootBox;
  uint32_t depth = 0;                  // wide depth of the deepest leaf

  uint32_t nodeCount() const { return static_cast<uint32_t>(nodes.size()); }
  // A view for the traversal with the given per-slot Woop triangles, indices and positions.
  CwbvhView view(const WoopTriangle* woop, const uint32_t* indices, const float* positions) const;
};

// The compressed layout of `wide` (width <= 8), quantized with its boxes of frame `frame`.
// Children are placed in slots by the direction of their box centre from the node's centre,
// averaged over all frames of `wide` (greedy assignment as in the paper). Throws tsah::DataError
// when the tree is wider than 8 or a node's leaf children hold more than 64 triangles,
// tsah::ConfigError when `wide` has no frame `frame`.
CwbvhTree buildCwbvh(const WideBvh& wide, uint32_t frame = 0);

// The 8-wide T-SAH collapse of a flat tree over all its frames for an objective (the tree file's
// BvhBuildInfo::objective), then buildCwbvh: WideCollapser(wideCollapseConfig(objective, 8)), so
// its k, cT, cI and largest leaf as in the CPU wide layouts, the largest leaf capped at
// kCwbvhMaxLeafTriangles (a node's leaves hold at most 64 triangles). The default objective:
// k = 0, cT = 3, cI = 2, leaves of at most 8.
CwbvhTree buildCwbvh(const FlatBvh& flat, const Objective& objective = {});

// Per frame: exact leaf boxes from the triangles, exact boxes bottom-up, every node re-quantized
// (cwbvhQuantize), rootBox. Exactly the GPU runtime's refit.
void refitCwbvh(CwbvhTree& tree, std::span<const uint32_t> indices, std::span<const float> positions);

// The nodes grouped by height (0: every child a leaf; otherwise one more than the highest interior
// child), lowest first, ascending indices within a group: a refit that finishes each group before
// the next reads only finished children (the GPU runtime's refit runs a launch per group). Group h
// is nodes[starts[h], starts[h + 1]); a one-leaf tree has no groups (starts = {0}).
struct CwbvhLevels {
  std::vector<uint32_t> nodes;
  std::vector<uint32_t> starts;
};
CwbvhLevels cwbvhLevels(const CwbvhTree& tree);

// Structure (references in range, every slot reached once, leaf ranges covering triIndex once,
// triangle offsets < 64) and, when boxes are given (exactBoxes current), that every decoded child
// box contains its exact box. Returns the first violation.
std::optional<std::string> validateCwbvh(const CwbvhTree& tree, bool checkBoxes = true);

}  // namespace tsah
