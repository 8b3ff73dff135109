#pragma once
// Private to libtsah: how the CPU refits (binary and wide) split a tree in depth-first pre-order
// (the subtree of interior node i is [i, ends[i])) for a parallel bottom-up pass.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

namespace tsah::detail {

// About 8 disjoint subtrees per thread (each a contiguous index range, refitted in parallel,
// larger indices first; none split below minGrain nodes) and the nodes above them, in descending
// order (refitted afterwards on one thread, children before parents). interiorChildren(i, push)
// calls push(c) for every interior child c of node i. minGrain: 64 for a binary tree; a wide
// node holds several binary nodes' work, so wide trees pass less.
template <class InteriorChildren>
void planParallelRefit(const std::vector<uint32_t>& ends, uint32_t threads, const InteriorChildren& interiorChildren,
                       std::vector<std::pair<uint32_t, uint32_t>>& subtrees, std::vector<uint32_t>& top,
                       uint32_t minGrain = 64) {
  subtrees.clear();
  top.clear();
  if (ends.empty()) return;
  const uint32_t grain = std::max<uint32_t>(minGrain, uint32_t(ends.size()) / (8 * std::max(1u, threads)));
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    if (ends[i] - i <= grain) {
      subtrees.push_back({i, ends[i]});
      continue;
    }
    top.push_back(i);
    interiorChildren(i, [&](uint32_t c) { stack.push_back(c); });
  }
  std::sort(top.begin(), top.end(), std::greater<>());
}

// The part of a plan above that must run when only some subtrees move (nodeMoves[i] != 0: node i's
// subtree holds a moving triangle): per planned subtree that moves, its moving nodes in ascending
// order (taskNodes[taskStart[t]] up to taskNodes[taskStart[t + 1]]), and the moving nodes above
// the subtrees, in the plan's descending order. A node that does not move keeps its boxes.
struct MovingRefitPlan {
  std::vector<uint32_t> taskNodes, taskStart{0}, top;
  std::size_t taskCount() const { return taskStart.size() - 1; }
};

inline MovingRefitPlan planMovingRefit(const std::vector<std::pair<uint32_t, uint32_t>>& subtrees,
                                       const std::vector<uint32_t>& top, const std::vector<uint8_t>& nodeMoves) {
  MovingRefitPlan plan;
  for (const auto& [root, end] : subtrees) {
    for (uint32_t i = root; i < end; ++i)
      if (nodeMoves[i]) plan.taskNodes.push_back(i);
    if (plan.taskNodes.size() > plan.taskStart.back()) plan.taskStart.push_back(uint32_t(plan.taskNodes.size()));
  }
  for (uint32_t i : top)
    if (nodeMoves[i]) plan.top.push_back(i);
  return plan;
}

}  // namespace tsah::detail
