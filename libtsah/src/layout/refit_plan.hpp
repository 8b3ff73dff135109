#pragma once
// Private to libtsah: how the CPU refits (binary and wide) split a tree in depth-first pre-order
// (the subtree of interior node i is [i, ends[i])) for a parallel bottom-up pass.
#include <algorithm>
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

}  // namespace tsah::detail
