#include "tsah/core/bvh.hpp"

#include <algorithm>
#include <cstring>
#include <functional>

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
  for (uint32_t n : childrenFirstOrder(bvh)) {
    const BvhNode& node = bvh.nodes[n];
    Aabb* out = boxesOf(n);
    const Aabb* left = node.isLeaf() ? nullptr : boxesOf(node.left);
    const Aabb* right = node.isLeaf() ? nullptr : boxesOf(node.right);
    for (uint32_t f = 0; f < prims.frameCount; ++f) {
      Aabb b;
      if (node.isLeaf()) {
        for (uint32_t i = 0; i < node.primCount; ++i)
          b.extend(prims.at(f, bvh.primIds[node.primBegin + i]));
      } else {
        b = merge(left[f], right[f]);
      }
      out[f] = b;
    }
  }
}

void refit(Bvh& bvh, const PrimitiveBoxes& prims) {
  if (bvh.nodes.empty()) return;
  bvh.frameCount = prims.frameCount;
  bvh.boxes.assign(bvh.nodes.size() * std::size_t(prims.frameCount), Aabb{});
  refitInto(bvh, prims, [&bvh](uint32_t n) { return &bvh.box(n, 0); });
}

std::optional<std::string> validate(const Bvh& bvh, const PrimitiveBoxes* prims) {
  const auto nodeCount = bvh.nodes.size();
  if (nodeCount == 0) return bvh.primIds.empty() ? std::nullopt : std::optional<std::string>("no nodes");
  if (bvh.root >= nodeCount) return "root index out of range";
  if (bvh.nodes[bvh.root].parent != kInvalidIndex) return "root has a parent";
  if (bvh.boxes.size() != nodeCount * std::size_t(bvh.frameCount))
    return "box array size does not match nodes x frames";
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
