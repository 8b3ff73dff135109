// limitDepth (tsah/core/bvh.hpp): the bound on the depth of every tree the library makes.
#include <algorithm>
#include <string>
#include <vector>

#include "core/parallel_tree.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/bvh.hpp"

namespace tsah {

namespace {

// Depth of a balanced binary tree over `leaves` leaves: ceil(log2(leaves)).
uint32_t balancedDepth(uint32_t leaves) {
  uint32_t depth = 0;
  while ((uint64_t(1) << depth) < leaves) ++depth;
  return depth;
}

// Rebuilds the subtree of `top` as a balanced tree over its leaves, reusing its interior nodes
// (`top` stays its root, so its parent link holds).
void rebuildBalanced(Bvh& bvh, uint32_t top) {
  std::vector<uint32_t> leaves, interior;
  std::vector<uint32_t> stack{top};
  while (!stack.empty()) {  // left to right
    const uint32_t n = stack.back();
    stack.pop_back();
    if (bvh.nodes[n].isLeaf()) {
      leaves.push_back(n);
    } else {
      interior.push_back(n);
      stack.push_back(bvh.nodes[n].right);
      stack.push_back(bvh.nodes[n].left);
    }
  }
  const bool hasBoxes = bvh.boxes.size() == bvh.nodes.size() * std::size_t(bvh.frameCount);
  std::size_t nextInterior = 0;  // interior[0] is `top`, taken first
  // Recursion depth: the balanced depth of the subtree (at most 32 for 32-bit node counts).
  auto build = [&](auto& self, std::size_t lo, std::size_t hi, uint32_t parent) -> uint32_t {
    if (hi - lo == 1) {
      bvh.nodes[leaves[lo]].parent = parent;
      return leaves[lo];
    }
    const uint32_t n = interior[nextInterior++];
    const std::size_t mid = lo + (hi - lo) / 2;
    BvhNode& node = bvh.nodes[n];
    node.parent = parent;
    node.left = self(self, lo, mid, n);
    node.right = self(self, mid, hi, n);
    if (hasBoxes)
      for (uint32_t f = 0; f < bvh.frameCount; ++f)
        bvh.box(n, f) = merge(bvh.box(bvh.nodes[n].left, f), bvh.box(bvh.nodes[n].right, f));
    return n;
  };
  build(build, 0, leaves.size(), bvh.nodes[top].parent);
}

}  // namespace

bool limitDepth(Bvh& bvh, uint32_t maxDepth) {
  if (bvh.nodes.empty()) return false;
  // Most trees are shallow enough: their height alone, subtrees in parallel, without the arrays.
  const uint32_t treeHeight = detail::reduceTree<uint32_t>(
      bvh.root, [&](uint32_t n) { return detail::shapeOf(bvh, n); }, [](uint32_t) { return 0u; },
      [](uint32_t, uint32_t left, uint32_t right) { return 1 + std::max(left, right); },
      detail::parallelTreeLevels(bvh.nodes.size()));
  if (treeHeight <= maxDepth) return false;
  // Height (levels below) and leaf count of every subtree, bottom-up.
  std::vector<uint32_t> height(bvh.nodes.size(), 0), leaves(bvh.nodes.size(), 1);
  for (uint32_t n : childrenFirstOrder(bvh)) {
    const BvhNode& node = bvh.nodes[n];
    if (node.isLeaf()) continue;
    height[n] = 1 + std::max(height[node.left], height[node.right]);
    leaves[n] = leaves[node.left] + leaves[node.right];
  }
  if (height[bvh.root] <= maxDepth) return false;
  if (balancedDepth(leaves[bvh.root]) > maxDepth)
    throw ConfigError("tree depth limit " + std::to_string(maxDepth) + ": too small for " +
                      std::to_string(leaves[bvh.root]) + " leaves");
  // Top-down: a subtree that is too deep keeps its root when both children can be made shallow
  // enough on their own, and is rebuilt balanced otherwise (the lowest subtrees that must change).
  std::vector<std::pair<uint32_t, uint32_t>> stack{{bvh.root, 0}};
  while (!stack.empty()) {
    const auto [n, depth] = stack.back();
    stack.pop_back();
    if (depth + height[n] <= maxDepth) continue;
    const BvhNode& node = bvh.nodes[n];
    const bool childrenFixable = depth + 1 + balancedDepth(leaves[node.left]) <= maxDepth &&
                                 depth + 1 + balancedDepth(leaves[node.right]) <= maxDepth;
    if (childrenFixable) {
      stack.push_back({node.left, depth + 1});
      stack.push_back({node.right, depth + 1});
    } else {
      rebuildBalanced(bvh, n);
    }
  }
  return true;
}

}  // namespace tsah
