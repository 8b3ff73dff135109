#include "tsah/layout/refit_parts.hpp"

#include <algorithm>

#include "tsah/base/error.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah {

uint32_t RefitParts::maxNodeCount() const {
  uint32_t most = 0;
  for (const RefitPart& p : parts) most = std::max(most, p.nodeCount);
  return most;
}

namespace {

constexpr uint32_t kNotLocal = 0xffffffffu;

// Adds one part over `nodes` (interior nodes, ascending): local ids in that order, each node's
// parent as a local slot (kPartExitSlot for the part's root), and an item per child that is a leaf
// or the root of a subtree part (partOfRoot[child] != kNotLocal). The top (hasEntries) has no slot
// range.
void addPart(const FlatBvh& tree, const std::vector<uint32_t>& nodes, const std::vector<uint32_t>& parentSlot,
             const std::vector<uint32_t>& partOfRoot, bool hasEntries, std::vector<uint32_t>& localOf,
             RefitParts& out) {
  RefitPart part;
  part.firstNode = uint32_t(out.globalNode.size());
  part.nodeCount = uint32_t(nodes.size());
  part.firstItem = uint32_t(out.items.size());
  for (uint32_t k = 0; k < nodes.size(); ++k) localOf[nodes[k]] = k;
  for (const uint32_t n : nodes) {
    const uint32_t up = parentSlot[n];
    const bool inPart = up != kPartExitSlot && localOf[up >> 1] != kNotLocal;
    out.parentSlot.push_back(inPart ? (localOf[up >> 1] << 1) | (up & 1u) : kPartExitSlot);
    out.globalNode.push_back(n);
  }
  for (const uint32_t n : nodes) {
    const GpuBvhNode& node = tree.nodes[n];
    for (int side = 0; side < 2; ++side) {
      const int32_t ref = node.childRef(side);
      const uint32_t slot = (localOf[n] << 1) | uint32_t(side);
      if (isLeafRef(ref))
        out.items.push_back({slot, leafFirstSlot(ref), node.childCount(side)});
      else if (partOfRoot[uint32_t(ref)] != kNotLocal)
        out.items.push_back({slot, partOfRoot[uint32_t(ref)], kPartEntry});
    }
  }
  for (const uint32_t n : nodes) localOf[n] = kNotLocal;
  part.itemCount = uint32_t(out.items.size()) - part.firstItem;
  if (!hasEntries) {  // a subtree: its leaves' slots are consecutive (canonical order)
    uint32_t lo = UINT32_MAX, count = 0;
    for (uint32_t i = part.firstItem; i < out.items.size(); ++i) {
      lo = std::min(lo, out.items[i].first);
      count += out.items[i].count;
    }
    part.firstSlot = part.itemCount ? lo : 0;
    part.slotCount = count;
  }
  out.parts.push_back(part);
}

}  // namespace

RefitParts splitForBlockRefit(const FlatBvh& tree, uint32_t maxLeaves) {
  // Every tree with interior nodes has one with two leaf children: at least one subtree part.
  if (maxLeaves < 2) throw ConfigError("splitForBlockRefit: a part must be allowed at least 2 leaves");
  RefitParts out;
  const uint32_t n = tree.interiorCount;
  if (n == 0) {  // the tree is one leaf
    out.parts.push_back({0, 0, 0, 1, 0, tree.rootCount});
    out.items.push_back({kPartExitSlot, 0, tree.rootCount});
    return out;
  }
  // Parents (as slots) and leaves per subtree; children have larger indices (pre-order).
  std::vector<uint32_t> parentSlot(n, kPartExitSlot), leaves(n, 0);
  for (uint32_t i = 0; i < n; ++i)
    for (int side = 0; side < 2; ++side) {
      const int32_t ref = tree.nodes[i].childRef(side);
      if (!isLeafRef(ref)) parentSlot[uint32_t(ref)] = (i << 1) | uint32_t(side);
    }
  for (uint32_t i = n; i-- > 0;)
    for (int side = 0; side < 2; ++side) {
      const int32_t ref = tree.nodes[i].childRef(side);
      leaves[i] += isLeafRef(ref) ? 1u : leaves[uint32_t(ref)];
    }
  // Subtree roots: the highest nodes with at most maxLeaves leaves; the nodes above them: the top.
  std::vector<uint32_t> partOfRoot(n, kNotLocal), roots, top;
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    if (leaves[i] <= maxLeaves) {
      roots.push_back(i);
      continue;
    }
    top.push_back(i);
    for (int side = 1; side >= 0; --side) {
      const int32_t ref = tree.nodes[i].childRef(side);
      if (!isLeafRef(ref)) stack.push_back(uint32_t(ref));
    }
  }
  std::sort(roots.begin(), roots.end());
  std::sort(top.begin(), top.end());
  std::vector<uint32_t> localOf(n, kNotLocal), nodes;
  const std::vector<uint32_t> noEntries(n, kNotLocal);
  for (uint32_t p = 0; p < roots.size(); ++p) {
    const uint32_t r = roots[p];
    uint32_t end = r + 1;  // pre-order: the subtree of r is [r, end)
    while (end < n && parentSlot[end] != kPartExitSlot && (parentSlot[end] >> 1) >= r && (parentSlot[end] >> 1) < end)
      ++end;
    nodes.resize(end - r);
    for (uint32_t k = 0; k < nodes.size(); ++k) nodes[k] = r + k;
    addPart(tree, nodes, parentSlot, noEntries, false, localOf, out);
    partOfRoot[r] = p;
  }
  out.hasTop = !top.empty();
  if (out.hasTop) addPart(tree, top, parentSlot, partOfRoot, true, localOf, out);
  return out;
}

}  // namespace tsah
