#include "tsah/optimize/leaf_collapser.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <vector>

#include "core/parallel_tree.hpp"

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
// becoming leaves, without boxes; origin[i] is the source node of output node i. The numbering is
// that of one walk with a stack: a node's two children get the next two indices when it is
// expanded, then the left child's subtree is numbered, then the right's, and each leaf's
// primitives follow the previous leaf's. So a subtree's place is known from the sizes of the
// subtrees before it: the top levels are measured, then placed, in parallel.
class Compaction {
 public:
  Compaction(const CollapseSource& source, std::span<const uint8_t> asLeaf, Bvh& out, std::vector<uint32_t>& origin)
      : source_(source), asLeaf_(asLeaf), out_(out), origin_(origin), levels_(detail::parallelTreeLevels(source.nodeCount)),
        sizes_(detail::topLevelSlots(levels_)) {}

  void run() {
    const Size whole = measure();
    out_.nodes.assign(1 + whole.below, BvhNode{});
    origin_.assign(out_.nodes.size(), 0);
    out_.primIds.resize(whole.prims);
    origin_[0] = source_.root;
    place(source_.root, 0, 1, 0, levels_, 1);
  }

 private:
  // A compacted subtree: its nodes below its root, and its primitives.
  struct Size {
    uint64_t below = 0, prims = 0;
  };

  BvhNode node(uint32_t n) const { return source_.node(n); }
  bool becomesLeaf(uint32_t n, const BvhNode& node) const { return node.isLeaf() || (!asLeaf_.empty() && asLeaf_[n]); }

  // Calls visit(leaf node) for every source leaf below n, left to right.
  template <class Visit>
  void forEachLeaf(uint32_t n, const Visit& visit) const {
    std::vector<uint32_t> stack{n};
    while (!stack.empty()) {
      const BvhNode g = node(stack.back());
      stack.pop_back();
      if (g.isLeaf()) {
        visit(g);
      } else {
        stack.push_back(g.right);
        stack.push_back(g.left);
      }
    }
  }

  // The compacted size of the tree; the top levels' sizes are kept in sizes_ at their heap position
  // (root 1, children 2p and 2p + 1) for place().
  Size measure() {
    return detail::reduceTree<Size>(
        source_.root,
        [&](uint32_t n) {
          const BvhNode g = node(n);
          return detail::TreeNodeShape{becomesLeaf(n, g), g.left, g.right};
        },
        [&](uint32_t n) {
          Size size;
          forEachLeaf(n, [&](const BvhNode& leaf) { size.prims += leaf.primCount; });
          return size;
        },
        [](uint32_t, Size left, Size right) { return Size{2 + left.below + right.below, left.prims + right.prims}; },
        levels_, &sizes_);
  }

  // Source node `from` at output index `index`; its descendants go from `base`, its primitives
  // from `primBase`.
  void place(uint32_t from, uint32_t index, uint64_t base, uint64_t primBase, int levels, std::size_t position) {
    const BvhNode top = node(from);
    if (!becomesLeaf(from, top) && levels > 0) {
      const auto left = uint32_t(base), right = uint32_t(base + 1);
      link(index, top, left, right);
      const Size leftSize = sizes_[2 * position];
      tbb::parallel_invoke(
          [&] { place(top.left, left, base + 2, primBase, levels - 1, 2 * position); },
          [&] { place(top.right, right, base + 2 + leftSize.below, primBase + leftSize.prims, levels - 1, 2 * position + 1); });
      return;
    }
    // One task: pairs (source node, output index), the left child on top of the stack.
    std::vector<std::pair<uint32_t, uint32_t>> open{{from, index}};
    while (!open.empty()) {
      const auto [m, at] = open.back();
      open.pop_back();
      const BvhNode g = node(m);
      if (becomesLeaf(m, g)) {
        out_.nodes[at].primBegin = uint32_t(primBase);
        forEachLeaf(m, [&](const BvhNode& leaf) {
          for (uint32_t i = 0; i < leaf.primCount; ++i) out_.primIds[primBase++] = source_.primIds[leaf.primBegin + i];
        });
        out_.nodes[at].primCount = uint32_t(primBase) - out_.nodes[at].primBegin;
        continue;
      }
      const auto left = uint32_t(base), right = uint32_t(base + 1);
      base += 2;
      link(at, g, left, right);
      open.push_back({g.right, right});
      open.push_back({g.left, left});
    }
  }

  void link(uint32_t index, const BvhNode& from, uint32_t left, uint32_t right) {
    out_.nodes[index].left = left;
    out_.nodes[index].right = right;
    out_.nodes[left].parent = out_.nodes[right].parent = index;
    origin_[left] = from.left;
    origin_[right] = from.right;
  }

  const CollapseSource& source_;
  std::span<const uint8_t> asLeaf_;
  Bvh& out_;
  std::vector<uint32_t>& origin_;
  int levels_;
  std::vector<Size> sizes_;
};

Bvh compactTopology(const CollapseSource& source, std::span<const uint8_t> asLeaf, std::vector<uint32_t>& origin) {
  Bvh out;
  out.frameCount = source.frameCount;
  origin.clear();
  if (source.nodeCount == 0) return out;
  Compaction(source, asLeaf, out, origin).run();
  return out;
}

// The boxes of a compacted tree copied from the source through origin.
void copyBoxes(const CollapseSource& source, std::span<const uint32_t> origin, Bvh& out) {
  out.boxes.resize(origin.size() * std::size_t(source.frameCount));
  tbb::parallel_for(std::size_t(0), origin.size(), [&](std::size_t i) {
    source.boxes(origin[i], out.boxes.data() + i * source.frameCount);
  });
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
  std::vector<Aabb> rootBoxes(frames);
  source.boxes(source.root, rootBoxes.data());
  std::vector<double> factor(frames, 0.0);
  for (uint32_t f = 0; f < frames; ++f) {
    const double rootArea = rootBoxes[f].area();
    factor[f] = rootArea > 0.0 ? weights[f] / rootArea : 0.0;
  }
  const double ct = config_.cost.ct, ci = config_.cost.ci;
  std::vector<uint8_t> asLeaf(source.nodeCount, 0);
  const auto weightedArea = [&](uint32_t n) {
    thread_local std::vector<Aabb> boxes;
    boxes.resize(frames);
    source.boxes(n, boxes.data());
    double area = 0.0;
    for (uint32_t f = 0; f < frames; ++f) area += factor[f] * boxes[f].area();
    return area;
  };
  // Children first, subtrees in parallel: (primitives, cost as kept) of each subtree.
  using Kept = std::pair<uint32_t, double>;
  detail::reduceTree<Kept>(
      source.root,
      [&](uint32_t n) {
        const BvhNode node = source.node(n);
        return detail::TreeNodeShape{node.isLeaf(), node.left, node.right};
      },
      [&](uint32_t n) {
        const uint32_t count = source.node(n).primCount;
        return Kept{count, ci * count * weightedArea(n)};
      },
      [&](uint32_t n, Kept left, Kept right) {
        const double area = weightedArea(n);
        const uint32_t count = left.first + right.first;
        const double keep = ct * area + left.second + right.second;
        const double leaf = ci * count * area;
        if (count <= config_.maxLeafSize && leaf <= keep) {
          asLeaf[n] = 1;
          return Kept{count, leaf};
        }
        return Kept{count, keep};
      },
      detail::parallelTreeLevels(source.nodeCount));
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
