#pragma once
// Children-first work over a binary tree split into parallel tasks: each of the top levels hands
// its two subtrees to two tasks, and every subtree below them is walked by one task with an
// explicit stack (memory follows the depth, never the recursion). A node's value depends on its
// subtree alone, so the results are those of one sequential walk, whatever the scheduling.
#include <tbb/parallel_invoke.h>

#include <cstdint>
#include <utility>
#include <vector>

#include "tsah/core/bvh.hpp"

namespace tsah::detail {

// How many top levels split into tasks for a tree of `nodes` nodes: none for small trees (the
// tasks would cost more than the walk), else up to 2^10 subtree tasks.
inline int parallelTreeLevels(std::size_t nodes) { return nodes < (std::size_t(1) << 16) ? 0 : 10; }

// Slots for the values of the top `levels` levels by heap position (root 1, children 2p, 2p + 1).
inline std::size_t topLevelSlots(int levels) { return std::size_t(2) << levels; }

// A node's shape as the walk sees it.
struct TreeNodeShape {
  bool leaf;
  uint32_t left, right;
};

inline TreeNodeShape shapeOf(const Bvh& bvh, uint32_t n) {
  const BvhNode& node = bvh.nodes[n];
  return {node.isLeaf(), node.left, node.right};
}

// reduceTree's value of `root` (below) by one task: a walk with an explicit stack.
template <class Value, class ShapeOf, class Leaf, class Inner>
Value reduceSubtree(uint32_t root, const ShapeOf& shapeOf, const Leaf& leaf, const Inner& inner) {
  struct Open {
    uint32_t node;
    bool expanded;
  };
  std::vector<Open> stack{{root, false}};
  std::vector<Value> done;  // values of finished subtrees whose parent is still open
  while (!stack.empty()) {
    const uint32_t n = stack.back().node;
    const TreeNodeShape s = shapeOf(n);
    if (!s.leaf && !stack.back().expanded) {
      stack.back().expanded = true;
      stack.push_back({s.right, false});
      stack.push_back({s.left, false});
      continue;
    }
    stack.pop_back();
    if (s.leaf) {
      done.push_back(leaf(n));
      continue;
    }
    Value right = std::move(done.back());
    done.pop_back();
    Value left = std::move(done.back());
    done.pop_back();
    done.push_back(inner(n, std::move(left), std::move(right)));
  }
  return std::move(done.back());
}

// value(root) where value(n) = leaf(n) for a leaf and inner(n, value(left), value(right)) for an
// interior node; shapeOf(n) gives a node's TreeNodeShape. leaf and inner run concurrently for
// nodes of different subtrees: they may write per-node outputs, nothing shared. With `top`
// (topLevelSlots(parallelLevels) values), the values of the nodes in the parallel levels are kept
// at their heap position, for a second pass that places subtrees by the sizes before them.
template <class Value, class ShapeOf, class Leaf, class Inner>
Value reduceTree(uint32_t root, const ShapeOf& shapeOf, const Leaf& leaf, const Inner& inner, int parallelLevels,
                 std::vector<Value>* top = nullptr, std::size_t position = 1) {
  const Value value = [&]() -> Value {
    const TreeNodeShape shape = shapeOf(root);
    if (shape.leaf) return leaf(root);
    if (parallelLevels > 0) {
      Value left{}, right{};
      tbb::parallel_invoke(
          [&] { left = reduceTree<Value>(shape.left, shapeOf, leaf, inner, parallelLevels - 1, top, 2 * position); },
          [&] { right = reduceTree<Value>(shape.right, shapeOf, leaf, inner, parallelLevels - 1, top, 2 * position + 1); });
      return inner(root, std::move(left), std::move(right));
    }
    return reduceSubtree<Value>(root, shapeOf, leaf, inner);
  }();
  if (top != nullptr && position < top->size()) (*top)[position] = value;
  return value;
}

}  // namespace tsah::detail
