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

// About 8 disjoint subtrees per thread, balanced by weight(i) (the work in node i's subtree; each
// a contiguous index range, refitted in parallel, larger indices first; none split below minGrain)
// out of `total`, and the nodes above them, in descending order (refitted afterwards on one thread,
// children before parents). interiorChildren(i, push) calls push(c) for every interior child c of
// node i.
template <class InteriorChildren, class Weight>
void planWeightedRefit(const std::vector<uint32_t>& ends, uint64_t total, uint32_t threads,
                       const InteriorChildren& interiorChildren, const Weight& weight,
                       std::vector<std::pair<uint32_t, uint32_t>>& subtrees, std::vector<uint32_t>& top,
                       uint32_t minGrain) {
  subtrees.clear();
  top.clear();
  if (ends.empty()) return;
  const uint64_t grain = std::max<uint64_t>(minGrain, total / (8 * std::max(1u, threads)));
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    if (weight(i) <= grain) {
      subtrees.push_back({i, ends[i]});
      continue;
    }
    top.push_back(i);
    interiorChildren(i, [&](uint32_t c) { stack.push_back(c); });
  }
  std::sort(top.begin(), top.end(), std::greater<>());
}

// The full refit's plan: weighted by subtree size (minGrain: 64 for a binary tree; a wide node holds
// several binary nodes' work, so wide trees pass less).
template <class InteriorChildren>
void planParallelRefit(const std::vector<uint32_t>& ends, uint32_t threads, const InteriorChildren& interiorChildren,
                       std::vector<std::pair<uint32_t, uint32_t>>& subtrees, std::vector<uint32_t>& top,
                       uint32_t minGrain = 64) {
  planWeightedRefit(
      ends, ends.size(), threads, interiorChildren, [&](uint32_t i) { return uint64_t(ends[i] - i); }, subtrees, top,
      minGrain);
}

// The refit of the moving nodes only (nodeMoves[i] != 0: node i's subtree holds a moving
// triangle), planned by their count, so that moving parts gathered in one region of the tree still
// spread over the threads: per planned subtree that moves, its moving nodes in ascending order
// (taskNodes[taskStart[t]] up to taskNodes[taskStart[t + 1]]), and the moving nodes above the
// subtrees, in descending order. A node that does not move keeps its boxes.
struct MovingRefitPlan {
  std::vector<uint32_t> taskNodes, taskStart{0}, top;
  std::size_t taskCount() const { return taskStart.size() - 1; }
};

template <class InteriorChildren>
MovingRefitPlan planMovingRefit(const std::vector<uint32_t>& ends, uint32_t threads,
                                const InteriorChildren& interiorChildren, const std::vector<uint8_t>& nodeMoves,
                                uint32_t minGrain) {
  std::vector<uint32_t> movingBefore(nodeMoves.size() + 1, 0);  // moving nodes below index i
  for (std::size_t i = 0; i < nodeMoves.size(); ++i) movingBefore[i + 1] = movingBefore[i] + (nodeMoves[i] ? 1 : 0);
  std::vector<std::pair<uint32_t, uint32_t>> subtrees;
  std::vector<uint32_t> top;
  planWeightedRefit(
      ends, movingBefore.back(), threads, interiorChildren,
      [&](uint32_t i) { return uint64_t(movingBefore[ends[i]] - movingBefore[i]); }, subtrees, top, minGrain);
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
