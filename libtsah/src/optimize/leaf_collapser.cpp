#include "tsah/optimize/leaf_collapser.hpp"

#include <algorithm>
#include <vector>

#include "tsah/base/assert.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/cost_terms.hpp"

namespace tsah {

namespace {

#ifndef NDEBUG
// Debug builds: validate() of a tree whose boxes are not computed yet (its structure alone).
std::optional<std::string> validateTopology(const Bvh& tree) {
  Bvh structure;
  structure.nodes = tree.nodes;
  structure.primIds = tree.primIds;
  structure.root = tree.root;
  structure.frameCount = 0;
  return validate(structure);
}
#endif

// Eq. 1 per frame, summed over nodes in the order `nodeAt(i)` lists them, exactly as frameCosts(Bvh)
// sums a tree whose node i is nodeAt(i): the same sums in the same order, so the same doubles.
template <typename NodeAt>
std::vector<double> costsInOrder(const CollapseSource& source, uint32_t count, uint32_t rootPosition,
                                 const CostModel& model, NodeAt&& nodeAt) {
  const uint32_t frames = source.frameCount;
  std::vector<double> costs(frames, 0.0);
  if (count == 0) return costs;
  std::vector<double> inner(frames, 0.0), leaves(frames, 0.0), rootArea(frames, 0.0);
  std::vector<Aabb> boxes(frames);
  uint64_t innerCount = 0, primCount = 0;
  for (uint32_t i = 0; i < count; ++i) {
    const auto [n, node] = nodeAt(i);
    source.boxes(n, boxes.data());
    for (uint32_t f = 0; f < frames; ++f) {
      const double area = boxes[f].area();
      if (node.isLeaf()) leaves[f] += area * node.primCount;
      else inner[f] += area;
      if (i == rootPosition) rootArea[f] = area;
    }
    if (node.isLeaf()) primCount += node.primCount;
    else ++innerCount;
  }
  for (uint32_t f = 0; f < frames; ++f)
    costs[f] = cost::frameCost(model.ct, model.ci, inner[f], leaves[f], rootArea[f], innerCount, primCount);
  return costs;
}

// The tree of `source` renumbered depth-first (see LeafCollapser::compact), nodes flagged in asLeaf
// becoming leaves, without boxes; origin[i] is the source node of output node i.
Bvh compactTopology(const CollapseSource& source, std::span<const uint8_t> asLeaf, std::vector<uint32_t>& origin) {
  Bvh out;
  out.frameCount = source.frameCount;
  origin.clear();
  if (source.nodeCount == 0) return out;
  const auto becomesLeaf = [&](uint32_t n, const BvhNode& node) {
    return node.isLeaf() || (!asLeaf.empty() && asLeaf[n]);
  };
  // Exact sizes first: vectors grown by doubling would hold up to twice the tree for a moment.
  std::size_t count = 0;
  std::vector<uint32_t> stack{source.root};
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    ++count;
    const BvhNode node = source.node(n);
    if (becomesLeaf(n, node)) continue;
    stack.push_back(node.left);
    stack.push_back(node.right);
  }
  out.nodes.reserve(count);
  origin.reserve(count);
  out.primIds.reserve(source.primIds.size());
  const auto addNode = [&](uint32_t from, uint32_t parent) {
    const auto index = static_cast<uint32_t>(out.nodes.size());
    out.nodes.emplace_back().parent = parent;
    origin.push_back(from);
    return index;
  };
  // Pairs (source node, new index); the stack gives a depth-first order with the left child first.
  std::vector<std::pair<uint32_t, uint32_t>> open{{source.root, addNode(source.root, kInvalidIndex)}};
  std::vector<uint32_t> gather;
  while (!open.empty()) {
    const auto [from, index] = open.back();
    open.pop_back();
    const BvhNode node = source.node(from);
    if (becomesLeaf(from, node)) {
      // Every primitive below `from`, leaves in depth-first order.
      out.nodes[index].primBegin = static_cast<uint32_t>(out.primIds.size());
      gather.assign(1, from);
      while (!gather.empty()) {
        const BvhNode g = source.node(gather.back());
        gather.pop_back();
        if (g.isLeaf()) {
          for (uint32_t i = 0; i < g.primCount; ++i) out.primIds.push_back(source.primIds[g.primBegin + i]);
        } else {
          gather.push_back(g.right);
          gather.push_back(g.left);
        }
      }
      out.nodes[index].primCount = static_cast<uint32_t>(out.primIds.size()) - out.nodes[index].primBegin;
      continue;
    }
    const uint32_t left = addNode(node.left, index);
    const uint32_t right = addNode(node.right, index);
    out.nodes[index].left = left;
    out.nodes[index].right = right;
    open.push_back({node.right, right});
    open.push_back({node.left, left});
  }
  return out;
}

// The boxes of a compacted tree copied from the source through origin.
void copyBoxes(const CollapseSource& source, std::span<const uint32_t> origin, Bvh& out) {
  out.boxes.resize(origin.size() * std::size_t(source.frameCount));
  for (std::size_t i = 0; i < origin.size(); ++i) source.boxes(origin[i], out.boxes.data() + i * source.frameCount);
}

}  // namespace

CollapseSource CollapseSource::of(const Bvh& bvh) {
  CollapseSource s;
  s.frameCount = bvh.frameCount;
  s.nodeCount = bvh.nodeCount();
  s.root = bvh.root;
  s.primIds = bvh.primIds;
  s.node = [&bvh](uint32_t n) { return bvh.nodes[n]; };
  s.boxes = [&bvh](uint32_t n, Aabb* out) { std::copy_n(&bvh.box(n, 0), bvh.frameCount, out); };
  return s;
}

LeafCollapser::LeafCollapser(Config config) : config_(config) {
  if (config_.maxLeafSize == 0) throw tsah::ConfigError("LeafCollapser: maxLeafSize must be >= 1");
  if (config_.k < 0) throw tsah::ConfigError("LeafCollapser: the exponent k must be >= 0");
}

Bvh LeafCollapser::compact(const Bvh& bvh, std::span<const uint8_t> asLeaf) {
  const CollapseSource source = CollapseSource::of(bvh);
  std::vector<uint32_t> origin;
  Bvh out = compactTopology(source, asLeaf, origin);
  copyBoxes(source, origin, out);
  return out;
}

std::vector<uint8_t> LeafCollapser::leafFlags(const CollapseSource& source, std::span<const double> weights) const {
  const uint32_t frames = source.frameCount;
  std::vector<Aabb> boxes(frames);
  source.boxes(source.root, boxes.data());
  std::vector<double> factor(frames, 0.0);
  for (uint32_t f = 0; f < frames; ++f) {
    const double rootArea = boxes[f].area();
    factor[f] = rootArea > 0.0 ? weights[f] / rootArea : 0.0;
  }
  const double ct = config_.cost.ct, ci = config_.cost.ci;
  std::vector<uint8_t> asLeaf(source.nodeCount, 0);
  // Post-order with an explicit stack; `done` holds (primitives, cost as kept) of finished
  // subtrees whose parent is still open, so the extra memory follows the depth, not the size.
  struct Open {
    uint32_t node;
    bool expanded;
  };
  std::vector<Open> stack{{source.root, false}};
  std::vector<std::pair<uint32_t, double>> done;
  while (!stack.empty()) {
    const uint32_t n = stack.back().node;
    const BvhNode node = source.node(n);
    if (!node.isLeaf() && !stack.back().expanded) {
      stack.back().expanded = true;
      stack.push_back({node.right, false});
      stack.push_back({node.left, false});
      continue;
    }
    stack.pop_back();
    source.boxes(n, boxes.data());
    double area = 0.0;
    for (uint32_t f = 0; f < frames; ++f) area += factor[f] * boxes[f].area();
    if (node.isLeaf()) {
      done.push_back({node.primCount, ci * node.primCount * area});
      continue;
    }
    const auto right = done.back();
    done.pop_back();
    const auto left = done.back();
    done.pop_back();
    const uint32_t count = left.first + right.first;
    const double keep = ct * area + left.second + right.second;
    const double leaf = ci * count * area;
    if (count <= config_.maxLeafSize && leaf <= keep) {
      asLeaf[n] = 1;
      done.push_back({count, leaf});
    } else {
      done.push_back({count, keep});
    }
  }
  return asLeaf;
}

Bvh LeafCollapser::collapsedTopology(const CollapseSource& source, std::vector<uint32_t>& origin) const {
  if (source.nodeCount == 0) return compactTopology(source, {}, origin);
  const std::vector<double> before = costsInOrder(source, source.nodeCount, source.root, config_.cost,
                                                  [&](uint32_t i) { return std::pair(i, source.node(i)); });
  const double costBefore = temporalCost(before, config_.k);
  std::vector<double> weights = temporalWeights(before, config_.k);
  // k = 0 needs one pass; k > 0 may need the weights of the collapsed tree (see the header).
  const int attempts = config_.k == 0 ? 1 : 4;
  for (int attempt = 0; attempt < attempts; ++attempt) {
    Bvh collapsed = compactTopology(source, leafFlags(source, weights), origin);
    const std::vector<double> after =
        costsInOrder(source, collapsed.nodeCount(), collapsed.root, config_.cost,
                     [&](uint32_t i) { return std::pair(origin[i], collapsed.nodes[i]); });
    // Summation order differs between the trees: allow for rounding in the last digits.
    if (temporalCost(after, config_.k) <= costBefore * (1.0 + 1e-12)) return collapsed;
    weights = temporalWeights(after, config_.k);
  }
  return compactTopology(source, {}, origin);
}

Bvh LeafCollapser::collapse(const Bvh& bvh) const {
  const CollapseSource source = CollapseSource::of(bvh);
  std::vector<uint32_t> origin;
  Bvh out = collapsedTopology(source, origin);
  copyBoxes(source, origin, out);
  limitDepth(out);
  TSAH_ASSERT_VALID(validate(out), "leaf collapse: the collapsed tree");
  return out;
}

Bvh LeafCollapser::collapseTopology(const CollapseSource& source) const {
  std::vector<uint32_t> origin;
  Bvh out = collapsedTopology(source, origin);
  TSAH_ASSERT_VALID(validateTopology(out), "leaf collapse: the collapsed topology");
  return out;
}

}  // namespace tsah
