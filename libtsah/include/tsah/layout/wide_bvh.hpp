#pragma once
// Wide (4- or 8-ary) BVH topology derived once from a binary tsah::Bvh, fixed for the whole
// animation, so every frame is still only a refit. The CPU SIMD layout (wide_layout.hpp) and the
// GPU's compressed wide nodes are built from this one description.
//
// Which binary nodes to merge is chosen by the cost-optimal collapse of Ylitie, Karras and Laine
// (2017), with the multi-frame weighted area of the T-SAH cost instead of a one-frame area:
//
//   A(B) = sum_i w_i * area(B_i) / S_i
//
// over the frames stored in the binary tree (the representative frames the optimizer used), with
// S_i the root's area in frame i and w_i the T-SAH frame weights of the binary tree
// (temporalWeights(frameCosts(bvh), k), summing to 1). A frame whose root has no area counts every
// node with ratio 1 (the limit cost.hpp defines for such frames). For every binary node n the
// dynamic programme knows the cheapest way to represent n's subtree as
//   - one leaf (all its triangles; allowed when there are at most maxLeafSize of them, and always
//     for a leaf of the binary tree):                       cost cI * count * A(n)
//     (cI * ceil(count / leafPacket) * A(n) when the leaf is tested leafPacket triangles at once)
//   - one wide interior node (its children are at most `width` slots distributed over n's two
//     binary children):                                     cost cT * A(n) + cost of the slots
//   - i slots (i = 1..width) handed to the parent's wide node: n dissolves, its two binary
//     children share the i slots.
// With leafPacket = 1 the result minimises sum_i w_i * C_i (Eq. 1 of the paper, with the wide tree's interior nodes
// and leaves) over every wide tree whose nodes are nodes of the binary tree; for k = 0 that is
// exactly the average cost C~^0. The binary tree itself is one such tree (if its leaves fit), so
// with equal constants the wide tree never costs more than the binary one.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/layout/gpu_layout.hpp"  // the child reference encoding (makeLeafRef, leafFirstSlot)

namespace tsah {

inline constexpr uint32_t kMaxWideWidth = 8;

// One child slot of a wide interior node. Same reference encoding as GpuBvhNode (gpu_layout.hpp):
// ref >= 0 is the index of an interior node (count == 0); ref < 0 is a leaf holding the triangle
// slots [~ref, ~ref + count) of WideBvh::primIds (1 <= count).
struct WideChild {
  int32_t ref = 0;
  uint32_t count = 0;

  bool isLeaf() const { return isLeafRef(ref); }
  uint32_t firstPrim() const { return leafFirstSlot(ref); }
};

// An interior node: its children are children[firstChild, firstChild + childCount),
// 2 <= childCount <= width, in the left-to-right order of the binary tree.
struct WideNode {
  uint32_t firstChild = 0;
  uint32_t childCount = 0;
};

// The wide tree as plain data.
//
// Order (relied upon by the refits and traversals): interior nodes are numbered in depth-first
// pre-order, so node 0 is the root when there is one, every interior child has a larger index than
// its parent, and the interior nodes of the subtree rooted at i are exactly [i, subtreeEnd(i)).
// Every leaf owns a contiguous range of primIds; the ranges cover primIds exactly once.
//
// Boxes: one per child slot per frame, childBoxes[slot * frameCount + frame] (slot indexes
// `children`), plus the root's box per frame. A child's box is the box of the binary node it came
// from, so it encloses everything below it in that frame.
struct WideBvh {
  uint32_t width = 8;                 // the most children a node may have (2..kMaxWideWidth)
  uint32_t frameCount = 1;
  int32_t rootRef = makeLeafRef(0);              // interior node 0, or a leaf when the whole tree is one leaf
  uint32_t rootCount = 0;             // triangles of the root when it is a leaf, else 0
  std::vector<WideNode> nodes;
  std::vector<WideChild> children;
  std::vector<uint32_t> primIds;      // triangle slot -> primitive (triangle) id
  std::vector<Aabb> childBoxes;       // children.size() * frameCount, slot-major
  std::vector<Aabb> rootBoxes;        // frameCount

  uint32_t nodeCount() const { return static_cast<uint32_t>(nodes.size()); }
  uint32_t primCount() const { return static_cast<uint32_t>(primIds.size()); }
  uint32_t leafCount() const;
  uint32_t depth() const;  // deepest leaf (a root leaf: 0; a leaf child of the root: 1)
  const Aabb& childBox(uint32_t slot, uint32_t frame) const {
    return childBoxes[std::size_t(slot) * frameCount + frame];
  }
  Aabb& childBox(uint32_t slot, uint32_t frame) { return childBoxes[std::size_t(slot) * frameCount + frame]; }
};

class WideCollapser {
 public:
  // The objective (Objective: cT per wide interior node visit, cI per triangle test, the T-SAH
  // exponent of the frame weights w_i = C_i^k of the binary tree, and the largest leaf the collapse
  // makes; a leaf of the binary tree is kept whole even when larger) plus the node shape.
  struct Config : Objective {
    uint32_t width = 8;        // children per wide node (the CPU layouts use 4 and 8; 2..8 allowed)
    uint32_t leafPacket = 1;   // triangles tested at once: a leaf of j costs cI * ceil(j / leafPacket)
                               // (1: Eq. 1; the SIMD layouts use their width, since testing one
                               // packet of N triangles costs about as much as testing one)
  };

  WideCollapser() = default;
  explicit WideCollapser(Config config);
  const Config& config() const { return config_; }

  // The cost-optimal wide tree of `bvh` (which must pass tsah::validate and hold at least one
  // primitive) over the frames stored in it. Deterministic. O(nodes * (frames + width^2)).
  // Throws tsah::ConfigError for an invalid config or weights, tsah::DataError for an invalid tree.
  WideBvh collapse(const Bvh& bvh) const;

  // The same with given frame weights (one per frame of bvh, non-negative, not all zero; scaled to
  // sum 1). Returns the minimum of sum_i w_i * C_i it reached (also wideWeightedCost of the result).
  WideBvh collapse(const Bvh& bvh, std::span<const double> weights, double* weightedCost = nullptr) const;

 private:
  Config config_;
};

// The collapse a tree's objective asks for (BvhBuildInfo::objective of its file): its cost
// constants, T-SAH exponent and maximum leaf size.
WideCollapser::Config wideCollapseConfig(const Objective& objective, uint32_t width = 8);

// Eq. 1 of the paper for the wide tree in one of its frames: (cT * sum over interior nodes of
// S_N(i) + cI * sum over leaves of j_N * S_N(i)) / S_i, with the degenerate-frame rule of cost.hpp.
double wideFrameCost(const WideBvh& wide, uint32_t frame, const CostModel& model = {});
std::vector<double> wideFrameCosts(const WideBvh& wide, const CostModel& model = {});
// sum_i w_i * C_i for weights scaled to sum 1: what WideCollapser minimises.
double wideWeightedCost(const WideBvh& wide, std::span<const double> weights, const CostModel& model = {});

// Recomputes every box (all frames of prims; wide.frameCount becomes prims.frameCount) bottom-up
// from the primitive boxes.
void refitWide(WideBvh& wide, const PrimitiveBoxes& prims);

// For each interior node i, one past the last interior node of its subtree.
std::vector<uint32_t> wideSubtreeEnds(const WideBvh& wide);

// Checks the structural rules above (references in range and in pre-order, 2..width children,
// leaf ranges contiguous and covering primIds, primIds a permutation, box counts) and, when prims
// is given, that every box contains its children's boxes and its triangles' boxes in every frame.
// Returns the first violation.
std::optional<std::string> validateWide(const WideBvh& wide, const PrimitiveBoxes* prims = nullptr);

}  // namespace tsah
