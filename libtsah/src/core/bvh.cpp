#include "tsah/core/bvh.hpp"

#include <algorithm>
#include <atomic>
#include <cstring>
#include <functional>

#include "core/parallel_tree.hpp"

namespace tsah {

void triangleBoxes(std::span<const uint32_t> indices, std::span<const float> positions,
                   std::span<Aabb> out) {
  const std::size_t triangles = indices.size() / 3;
  for (std::size_t t = 0; t < triangles; ++t) {
    Aabb b;
    for (int c = 0; c < 3; ++c) {
      const float* p = positions.data() + 3 * std::size_t(indices[3 * t + c]);
      b.extend(Vec3{p[0], p[1], p[2]});
    }
    out[t] = b;
  }
}

PrimitiveBoxes triangleBoxes(std::span<const uint32_t> indices, std::span<const float> positions,
                             uint32_t frameCount) {
  PrimitiveBoxes result;
  result.frameCount = frameCount;
  result.primCount = static_cast<uint32_t>(indices.size() / 3);
  result.boxes.resize(std::size_t(frameCount) * result.primCount);
  const std::size_t perFrame = frameCount ? positions.size() / frameCount : 0;
  for (uint32_t f = 0; f < frameCount; ++f)
    triangleBoxes(indices, positions.subspan(f * perFrame, perFrame),
                  std::span<Aabb>(result.boxes).subspan(std::size_t(f) * result.primCount,
                                                        result.primCount));
  return result;
}

uint32_t Bvh::leafCount() const {
  return static_cast<uint32_t>(
      std::count_if(nodes.begin(), nodes.end(), [](const BvhNode& n) { return n.isLeaf(); }));
}

uint32_t Bvh::depth() const {
  if (nodes.empty()) return 0;
  uint32_t deepest = 0;
  std::vector<std::pair<uint32_t, uint32_t>> stack{{root, 0}};
  while (!stack.empty()) {
    auto [n, d] = stack.back();
    stack.pop_back();
    deepest = std::max(deepest, d);
    if (!nodes[n].isLeaf()) {
      stack.push_back({nodes[n].left, d + 1});
      stack.push_back({nodes[n].right, d + 1});
    }
  }
  return deepest;
}

std::vector<uint32_t> childrenFirstOrder(const Bvh& bvh) {
  std::vector<uint32_t> order;
  if (bvh.nodes.empty()) return order;
  order.reserve(bvh.nodes.size());
  std::vector<uint32_t> stack{bvh.root};
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    order.push_back(n);
    if (!bvh.nodes[n].isLeaf()) {
      stack.push_back(bvh.nodes[n].left);
      stack.push_back(bvh.nodes[n].right);
    }
  }
  std::reverse(order.begin(), order.end());
  return order;
}

void refitInto(const Bvh& bvh, const PrimitiveBoxes& prims, const std::function<Aabb*(uint32_t node)>& boxesOf) {
  if (bvh.nodes.empty()) return;
  // Subtrees in parallel: each node's boxes come from its own subtree alone.
  struct None {};
  detail::reduceTree<None>(
      bvh.root, [&](uint32_t n) { return detail::shapeOf(bvh, n); },
      [&](uint32_t n) {
        const BvhNode& node = bvh.nodes[n];
        Aabb* out = boxesOf(n);
        for (uint32_t f = 0; f < prims.frameCount; ++f) {
          Aabb b;
          for (uint32_t i = 0; i < node.primCount; ++i) b.extend(prims.at(f, bvh.primIds[node.primBegin + i]));
          out[f] = b;
        }
        return None{};
      },
      [&](uint32_t n, None, None) {
        const BvhNode& node = bvh.nodes[n];
        Aabb* out = boxesOf(n);
        const Aabb* left = boxesOf(node.left);
        const Aabb* right = boxesOf(node.right);
        for (uint32_t f = 0; f < prims.frameCount; ++f) out[f] = merge(left[f], right[f]);
        return None{};
      },
      detail::parallelTreeLevels(bvh.nodes.size()));
}

void refit(Bvh& bvh, const PrimitiveBoxes& prims) {
  if (bvh.nodes.empty()) return;
  bvh.frameCount = prims.frameCount;
  bvh.boxes.assign(bvh.nodes.size() * std::size_t(prims.frameCount), Aabb{});
  refitInto(bvh, prims, [&bvh](uint32_t n) { return &bvh.box(n, 0); });
}

namespace {

// Whether the tree passes every check of validate()'s walk, the subtrees of the top levels
// checked in parallel (the root and the array sizes are checked already). It names no problem:
// validate() walks a failing tree again in order for the first one.
bool passesInParallel(const Bvh& bvh, const PrimitiveBoxes* prims) {
  const std::size_t nodeCount = bvh.nodes.size();
  std::vector<std::atomic<uint8_t>> seen(nodeCount), primSeen(bvh.primIds.size());
  std::atomic<bool> failed{false};
  const auto claim = [](std::atomic<uint8_t>& flag) { return flag.exchange(1, std::memory_order_relaxed) == 0; };
  struct Reached {
    uint64_t nodes = 0, prims = 0;
  };
  // Checks node n (claimed already) and claims its children; false at a problem.
  const auto check = [&](uint32_t n, Reached& reached) {
    const BvhNode& node = bvh.nodes[n];
    ++reached.nodes;
    if (node.isLeaf()) {
      if (std::size_t(node.primBegin) + node.primCount > bvh.primIds.size()) return false;
      for (uint32_t i = 0; i < node.primCount; ++i) {
        const uint32_t p = bvh.primIds[node.primBegin + i];
        if (p >= primSeen.size() || !claim(primSeen[p])) return false;
        ++reached.prims;
        if (prims)
          for (uint32_t f = 0; f < bvh.frameCount && f < prims->frameCount; ++f)
            if (!bvh.box(n, f).contains(prims->at(f, p))) return false;
      }
      return true;
    }
    for (uint32_t c : {node.left, node.right}) {
      if (c >= nodeCount || bvh.nodes[c].parent != n) return false;
      for (uint32_t f = 0; f < bvh.frameCount; ++f)
        if (!bvh.box(n, f).contains(bvh.box(c, f))) return false;
      if (!claim(seen[c])) return false;
    }
    return true;
  };
  const auto walk = [&](auto& self, uint32_t n, int levels) -> Reached {
    Reached reached;
    if (levels > 0) {
      if (!check(n, reached)) {
        failed = true;
        return reached;
      }
      if (bvh.nodes[n].isLeaf()) return reached;
      Reached left, right;
      tbb::parallel_invoke([&] { left = self(self, bvh.nodes[n].left, levels - 1); },
                           [&] { right = self(self, bvh.nodes[n].right, levels - 1); });
      return {reached.nodes + left.nodes + right.nodes, reached.prims + left.prims + right.prims};
    }
    std::vector<uint32_t> stack{n};
    while (!stack.empty() && !failed.load(std::memory_order_relaxed)) {
      const uint32_t m = stack.back();
      stack.pop_back();
      if (!check(m, reached)) {
        failed = true;
        break;
      }
      if (!bvh.nodes[m].isLeaf()) {
        stack.push_back(bvh.nodes[m].right);
        stack.push_back(bvh.nodes[m].left);
      }
    }
    return reached;
  };
  claim(seen[bvh.root]);
  const Reached reached = walk(walk, bvh.root, detail::parallelTreeLevels(nodeCount));
  return !failed && reached.nodes == nodeCount && reached.prims == primSeen.size() &&
         (!prims || prims->primCount == bvh.primIds.size());
}

}  // namespace

std::optional<std::string> validate(const Bvh& bvh, const PrimitiveBoxes* prims) {
  const auto nodeCount = bvh.nodes.size();
  if (nodeCount == 0) return bvh.primIds.empty() ? std::nullopt : std::optional<std::string>("no nodes");
  if (bvh.root >= nodeCount) return "root index out of range";
  if (bvh.nodes[bvh.root].parent != kInvalidIndex) return "root has a parent";
  if (bvh.boxes.size() != nodeCount * std::size_t(bvh.frameCount))
    return "box array size does not match nodes x frames";
  if (detail::parallelTreeLevels(nodeCount) > 0 && passesInParallel(bvh, prims)) return std::nullopt;
  std::vector<uint8_t> seen(nodeCount, 0);
  std::vector<uint32_t> primSeen(bvh.primIds.size(), 0);
  std::vector<uint32_t> stack{bvh.root};
  std::size_t reached = 0;
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    if (seen[n]) return "node " + std::to_string(n) + " is reachable twice (cycle or shared child)";
    seen[n] = 1;
    ++reached;
    const BvhNode& node = bvh.nodes[n];
    if (node.isLeaf()) {
      if (std::size_t(node.primBegin) + node.primCount > bvh.primIds.size())
        return "leaf " + std::to_string(n) + " range exceeds the primitive array";
      for (uint32_t i = 0; i < node.primCount; ++i) {
        const uint32_t p = bvh.primIds[node.primBegin + i];
        if (p >= primSeen.size()) return "leaf " + std::to_string(n) + " holds primitive id out of range";
        if (primSeen[p]++) return "primitive " + std::to_string(p) + " is in more than one leaf";
        if (prims)
          for (uint32_t f = 0; f < bvh.frameCount && f < prims->frameCount; ++f)
            if (!bvh.box(n, f).contains(prims->at(f, p)))
              return "leaf " + std::to_string(n) + " box does not contain primitive " +
                     std::to_string(p) + " in frame " + std::to_string(f);
      }
      continue;
    }
    for (uint32_t c : {node.left, node.right}) {
      if (c >= nodeCount) return "node " + std::to_string(n) + " has a child index out of range";
      if (bvh.nodes[c].parent != n)
        return "node " + std::to_string(c) + " does not point back to its parent " + std::to_string(n);
      for (uint32_t f = 0; f < bvh.frameCount; ++f)
        if (!bvh.box(n, f).contains(bvh.box(c, f)))
          return "node " + std::to_string(n) + " box does not contain child " + std::to_string(c) +
                 " in frame " + std::to_string(f);
      stack.push_back(c);
    }
  }
  if (reached != nodeCount)
    return std::to_string(nodeCount - reached) + " nodes are not reachable from the root";
  for (std::size_t p = 0; p < primSeen.size(); ++p)
    if (primSeen[p] != 1) return "primitive " + std::to_string(p) + " is in no leaf";
  if (prims && prims->primCount != bvh.primIds.size())
    return "tree holds " + std::to_string(bvh.primIds.size()) + " primitives, boxes " +
           std::to_string(prims->primCount);
  return std::nullopt;
}

}  // namespace tsah
