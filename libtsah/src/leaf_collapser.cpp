#include "tsah/leaf_collapser.hpp"

#include <algorithm>
#include <stdexcept>
#include <vector>

namespace tsah {

LeafCollapser::LeafCollapser(Config config) : config_(config) {
  if (config_.maxLeafSize == 0) throw std::invalid_argument("LeafCollapser: maxLeafSize must be >= 1");
  if (config_.k < 0) throw std::invalid_argument("LeafCollapser: the exponent k must be >= 0");
}

Bvh LeafCollapser::compact(const Bvh& bvh, std::span<const uint8_t> asLeaf) {
  Bvh out;
  out.frameCount = bvh.frameCount;
  if (bvh.nodes.empty()) return out;
  const uint32_t frames = bvh.frameCount;
  out.nodes.reserve(bvh.nodes.size());
  out.boxes.reserve(bvh.boxes.size());
  out.primIds.reserve(bvh.primIds.size());
  const auto makeLeaf = [&](uint32_t n) {
    return bvh.nodes[n].isLeaf() || (!asLeaf.empty() && asLeaf[n]);
  };
  const auto addNode = [&](uint32_t source, uint32_t parent) {
    const auto index = static_cast<uint32_t>(out.nodes.size());
    out.nodes.emplace_back().parent = parent;
    for (uint32_t f = 0; f < frames; ++f) out.boxes.push_back(bvh.box(source, f));
    return index;
  };
  // Pairs (source node, new index); the stack gives a depth-first order with the left child first.
  std::vector<std::pair<uint32_t, uint32_t>> stack{{bvh.root, addNode(bvh.root, kInvalidIndex)}};
  std::vector<uint32_t> gather;
  while (!stack.empty()) {
    const auto [source, index] = stack.back();
    stack.pop_back();
    if (makeLeaf(source)) {
      // Every primitive below `source`, leaves in depth-first order.
      out.nodes[index].primBegin = static_cast<uint32_t>(out.primIds.size());
      gather.assign(1, source);
      while (!gather.empty()) {
        const uint32_t n = gather.back();
        gather.pop_back();
        const BvhNode& node = bvh.nodes[n];
        if (node.isLeaf()) {
          for (uint32_t i = 0; i < node.primCount; ++i) out.primIds.push_back(bvh.primIds[node.primBegin + i]);
        } else {
          gather.push_back(node.right);
          gather.push_back(node.left);
        }
      }
      out.nodes[index].primCount = static_cast<uint32_t>(out.primIds.size()) - out.nodes[index].primBegin;
      continue;
    }
    const uint32_t left = addNode(bvh.nodes[source].left, index);
    const uint32_t right = addNode(bvh.nodes[source].right, index);
    out.nodes[index].left = left;
    out.nodes[index].right = right;
    stack.push_back({bvh.nodes[source].right, right});
    stack.push_back({bvh.nodes[source].left, left});
  }
  return out;
}

Bvh LeafCollapser::collapseWithWeights(const Bvh& bvh, std::span<const double> weights) const {
  const uint32_t frames = bvh.frameCount;
  std::vector<double> factor(frames, 0.0);
  for (uint32_t f = 0; f < frames; ++f) {
    const double rootArea = bvh.box(bvh.root, f).area();
    factor[f] = rootArea > 0.0 ? weights[f] / rootArea : 0.0;
  }
  const double ct = config_.cost.ct, ci = config_.cost.ci;
  std::vector<uint32_t> count(bvh.nodes.size(), 0);
  std::vector<double> cost(bvh.nodes.size(), 0.0);  // cost of the subtree as it will be kept
  std::vector<uint8_t> asLeaf(bvh.nodes.size(), 0);
  for (uint32_t n : childrenFirstOrder(bvh)) {
    const BvhNode& node = bvh.nodes[n];
    double area = 0.0;
    for (uint32_t f = 0; f < frames; ++f) area += factor[f] * bvh.box(n, f).area();
    if (node.isLeaf()) {
      count[n] = node.primCount;
      cost[n] = ci * node.primCount * area;
      continue;
    }
    count[n] = count[node.left] + count[node.right];
    const double keep = ct * area + cost[node.left] + cost[node.right];
    const double leaf = ci * count[n] * area;
    if (count[n] <= config_.maxLeafSize && leaf <= keep) {
      asLeaf[n] = 1;
      cost[n] = leaf;
    } else {
      cost[n] = keep;
    }
  }
  return compact(bvh, asLeaf);
}

Bvh LeafCollapser::collapse(const Bvh& bvh) const {
  if (bvh.nodes.empty()) return compact(bvh);
  const std::vector<double> before = frameCosts(bvh, config_.cost);
  const double costBefore = temporalCost(before, config_.k);
  std::vector<double> weights = temporalWeights(before, config_.k);
  // k = 0 needs one pass; k > 0 may need the weights of the collapsed tree (see the header).
  const int attempts = config_.k == 0 ? 1 : 4;
  for (int attempt = 0; attempt < attempts; ++attempt) {
    Bvh collapsed = collapseWithWeights(bvh, weights);
    const std::vector<double> after = frameCosts(collapsed, config_.cost);
    // Summation order differs between the trees: allow for rounding in the last digits.
    if (temporalCost(after, config_.k) <= costBefore * (1.0 + 1e-12)) return collapsed;
    weights = temporalWeights(after, config_.k);
  }
  return compact(bvh);
}

}  // namespace tsah
