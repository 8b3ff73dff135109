#pragma once
// Quality figures of one tree over the frames of an animation, for people looking at a tree:
// `tsah info TREE ANIMATION` prints them per frame and `tsah export --boxes` filters and colours
// boxes by them. Every cost is cost.hpp's (FrameCostEvaluator, CostParts, nodeCostTerm).
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "tsah/optimize/baselines.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"

namespace tsah {

// What a tree looks like, independent of the frame.
struct TreeShape {
  uint32_t innerCount = 0, leafCount = 0, primCount = 0;
  uint32_t depth = 0;  // of the deepest leaf (root 0)
  uint32_t smallestLeaf = 0, largestLeaf = 0;
  double meanLeafSize = 0.0;
  std::vector<uint32_t> leavesOfSize;  // [j]: leaves holding j primitives (index 0 unused)
};
TreeShape treeShape(const Bvh& bvh);

// Depth of every node (root 0), indexed by node; kInvalidIndex for nodes not reachable from the root.
std::vector<uint32_t> nodeDepths(const Bvh& bvh);

// One frame's figures.
struct FrameQuality {
  CostParts cost;  // Eq. 1 (cost.total()) and its interior and leaf sums
  // Means over the leaves weighted by their areas (the leaves a ray entering the root is likely to
  // visit): how deep and how full the leaves that rays meet are.
  double meanLeafDepth = 0.0, meanLeafSize = 0.0;
  // Surface area of each child of the root over its area in the first frame (1: unchanged);
  // {1, 1} when the root is a leaf.
  std::array<double, 2> rootChildGrowth{1.0, 1.0};
};

struct TreeQuality {
  std::vector<FrameQuality> frames;
  // Per node: the largest over the smallest share of the root's area the node's box covers over the
  // frames (1: it keeps its share of the scene; 10: at its worst it covers ten times more than at
  // its best). The nodes that make a refitted tree slow have large values.
  std::vector<double> nodeGrowth;
};

// Refits the tree's topology to every frame of `frames` (in order, one thread) and measures it.
TreeQuality evaluateTreeQuality(const Bvh& bvh, const FrameSource& frames, const CostModel& model = {});

// The node boxes of one frame, each node's share of that frame's cost (its nodeCostTerm over the sum
// of all terms; the shares add up to 1) and the frame's cost.
struct FrameBoxes {
  std::vector<Aabb> boxes;       // by node
  std::vector<double> costShare; // by node
  CostParts cost;
};
FrameBoxes frameBoxes(const Bvh& bvh, std::span<const Aabb> primBoxes, const CostModel& model = {});

}  // namespace tsah
