#include "tsah/layout/cwbvh_build.hpp"

#include <algorithm>
#include <deque>

#include "tsah/base/error.hpp"
#include "tsah/layout/cwbvh_convert.hpp"

namespace tsah {

namespace {

Aabb triangleBox(std::span<const uint32_t> indices, std::span<const float> positions, uint32_t tri) {
  Aabb box;
  for (int k = 0; k < 3; ++k) {
    const std::size_t v = indices[3 * std::size_t(tri) + k];
    box.extend(Vec3{positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]});
  }
  return box;
}

// Child -> slot assignment (cwbvhAssignSlots) by the children's directions from the node's centre,
// summed over all frames of the wide tree, so the order suits the whole animation.
std::vector<uint32_t> assignSlots(const WideBvh& wide, const WideNode& node) {
  const uint32_t n = node.childCount;
  Vec3 offset[kCwbvhWidth];
  Aabb boxes[kCwbvhWidth];
  for (uint32_t c = 0; c < n; ++c) offset[c] = Vec3{0, 0, 0};
  for (uint32_t f = 0; f < wide.frameCount; ++f) {
    for (uint32_t c = 0; c < n; ++c) boxes[c] = wide.childBox(node.firstChild + c, f);
    cwbvhAddCentreOffsets(boxes, n, offset);
  }
  uint32_t slotOf[kCwbvhWidth];
  cwbvhAssignSlots(offset, n, slotOf);
  return std::vector<uint32_t>(slotOf, slotOf + n);
}

}  // namespace

CwbvhView CwbvhTree::view(const WoopTriangle* woop, const uint32_t* indices, const float* positions) const {
  CwbvhView v;
  v.nodes = nodes.data();
  v.woop = woop;
  v.triIndex = triIndex.data();
  v.indices = indices;
  v.positions = positions;
  v.rootRef = rootRef;
  v.rootCount = rootCount;
  v.rootBox = rootBox;
  return v;
}

CwbvhTree buildCwbvh(const WideBvh& wide, uint32_t frame) {
  if (wide.width > kCwbvhWidth)
    throw tsah::DataError("compressed wide BVH: the wide tree has width " + std::to_string(wide.width) +
                          " (at most 8)");
  if (frame >= wide.frameCount) throw tsah::ConfigError("compressed wide BVH: no frame " + std::to_string(frame));
  CwbvhTree t;
  t.rootBox = wide.rootBoxes[frame];
  if (isLeafRef(wide.rootRef)) {
    t.rootRef = makeLeafRef(0);
    t.rootCount = wide.rootCount;
    const uint32_t first = leafFirstSlot(wide.rootRef);
    t.triIndex.assign(wide.primIds.begin() + first, wide.primIds.begin() + first + wide.rootCount);
    t.leaves.push_back({kCwbvhNoParent, 0, wide.rootCount});
    return t;
  }
  t.nodes.resize(wide.nodeCount());
  t.parentSlot.assign(wide.nodeCount(), kCwbvhNoParent);
  t.exactBoxes.resize(std::size_t(wide.nodeCount()) * kCwbvhWidth);
  t.triIndex.reserve(wide.primCount());
  std::vector<uint32_t> depth(wide.nodeCount(), 0);
  // Breadth-first: the interior children of a node get consecutive indices in slot order.
  std::deque<uint32_t> queue{uint32_t(wide.rootRef)};
  uint32_t next = 1, index = 0;
  for (; !queue.empty(); queue.pop_front(), ++index) {
    const WideNode& w = wide.nodes[queue.front()];
    if (w.childCount > kCwbvhWidth) throw tsah::DataError("compressed wide BVH: a node has more than 8 children");
    const std::vector<uint32_t> slotOf = assignSlots(wide, w);
    std::vector<int> childAt(kCwbvhWidth, -1);
    for (uint32_t c = 0; c < w.childCount; ++c) childAt[slotOf[c]] = int(c);
    CwbvhNode& n = t.nodes[index];
    n = CwbvhNode{};
    n.childBase = next;
    n.triBase = uint32_t(t.triIndex.size());
    for (uint32_t s = 0; s < kCwbvhWidth; ++s) {
      if (childAt[s] < 0) continue;
      const uint32_t slot = w.firstChild + uint32_t(childAt[s]);
      const WideChild& child = wide.children[slot];
      t.exactBoxes[std::size_t(index) * kCwbvhWidth + s] = wide.childBox(slot, frame);
      if (!child.isLeaf()) {
        n.meta[s] = kCwbvhInterior;
        t.parentSlot[next] = index * kCwbvhWidth + s;
        depth[next] = depth[index] + 1;
        t.depth = std::max(t.depth, depth[next]);
        ++next;
        queue.push_back(uint32_t(child.ref));
        continue;
      }
      const uint32_t offset = uint32_t(t.triIndex.size()) - n.triBase;
      if (offset + child.count > kCwbvhMaxNodeTriangles)
        throw tsah::DataError("compressed wide BVH: a node's leaves hold more than 64 triangles");
      n.meta[s] = uint8_t(kCwbvhLeaf | offset);
      t.leaves.push_back({index * kCwbvhWidth + s, uint32_t(t.triIndex.size()), child.count});
      t.triIndex.insert(t.triIndex.end(), wide.primIds.begin() + child.firstPrim(),
                        wide.primIds.begin() + child.firstPrim() + child.count);
      t.depth = std::max(t.depth, depth[index] + 1);
    }
    n.triCount = uint8_t(uint32_t(t.triIndex.size()) - n.triBase);
    cwbvhQuantize(n, &t.exactBoxes[std::size_t(index) * kCwbvhWidth]);
  }
  return t;
}

CwbvhTree buildCwbvh(const FlatBvh& flat, const Objective& objective) {
  WideCollapser::Config config = wideCollapseConfig(objective, kCwbvhWidth);
  config.maxLeafSize = std::min(config.maxLeafSize, kCwbvhMaxLeafTriangles);
  return buildCwbvh(WideCollapser(config).collapse(unflattenBvh(flat)));
}

void refitCwbvh(CwbvhTree& t, std::span<const uint32_t> indices, std::span<const float> positions) {
  for (const CwbvhLeaf& leaf : t.leaves) {
    Aabb box;
    for (uint32_t s = leaf.first; s < leaf.first + leaf.count; ++s)
      box.extend(triangleBox(indices, positions, t.triIndex[s]));
    if (leaf.nodeSlot == kCwbvhNoParent)
      t.rootBox = box;
    else
      t.exactBoxes[leaf.nodeSlot] = box;
  }
  // Children have larger indices than their parent: reverse order is bottom-up.
  for (uint32_t i = t.nodeCount(); i-- > 0;) {
    const Aabb box = cwbvhQuantize(t.nodes[i], &t.exactBoxes[std::size_t(i) * kCwbvhWidth]);
    if (t.parentSlot[i] == kCwbvhNoParent)
      t.rootBox = box;
    else
      t.exactBoxes[t.parentSlot[i]] = box;
  }
}

CwbvhLevels cwbvhLevels(const CwbvhTree& t) {
  std::vector<uint32_t> height(t.nodeCount(), 0);
  uint32_t maxHeight = 0;
  // Children have larger indices than their parent: reverse order sees every child first.
  for (uint32_t i = t.nodeCount(); i-- > 0;) {
    maxHeight = std::max(maxHeight, height[i]);
    if (t.parentSlot[i] == kCwbvhNoParent) continue;
    uint32_t& parent = height[t.parentSlot[i] / kCwbvhWidth];
    parent = std::max(parent, height[i] + 1);
  }
  CwbvhLevels levels;
  levels.starts.assign(t.nodes.empty() ? 1 : maxHeight + 2, 0);
  for (uint32_t h : height) ++levels.starts[h + 1];
  for (std::size_t h = 1; h < levels.starts.size(); ++h) levels.starts[h] += levels.starts[h - 1];
  levels.nodes.resize(t.nodeCount());
  std::vector<uint32_t> fill(levels.starts.begin(), levels.starts.end() - 1);
  for (uint32_t i = 0; i < t.nodeCount(); ++i) levels.nodes[fill[height[i]]++] = i;
  return levels;
}

std::optional<std::string> validateCwbvh(const CwbvhTree& t, bool checkBoxes) {
  const uint32_t slots = uint32_t(t.triIndex.size());
  std::vector<uint8_t> covered(slots, 0);
  auto cover = [&](uint32_t first, uint32_t count) -> std::optional<std::string> {
    if (first > slots || count > slots - first) return "leaf triangles out of range";
    for (uint32_t s = first; s < first + count; ++s)
      if (covered[s]++) return "triangle slot " + std::to_string(s) + " in two leaves";
    return std::nullopt;
  };
  if (isLeafRef(t.rootRef)) {
    if (!t.nodes.empty()) return "a one-leaf tree has nodes";
    if (auto p = cover(leafFirstSlot(t.rootRef), t.rootCount)) return p;
  } else {
    std::vector<uint8_t> reached(t.nodeCount(), 0);
    if (t.nodes.empty()) return "no root node";
    reached[0] = 1;
    for (uint32_t i = 0; i < t.nodeCount(); ++i) {
      const CwbvhNode& n = t.nodes[i];
      if (!reached[i]) return "node " + std::to_string(i) + " is not reached from the root";
      uint32_t rank = 0, occupied = 0;
      for (uint32_t s = 0; s < kCwbvhWidth; ++s) {
        if (n.isEmpty(s)) continue;
        ++occupied;
        if (n.isInterior(s)) {
          const uint64_t child = uint64_t(n.childBase) + rank++;
          if (child <= i || child >= t.nodeCount()) return "node " + std::to_string(i) + ": child out of order";
          if (reached[child]++) return "node " + std::to_string(child) + " reached twice";
          if (t.parentSlot[child] != i * kCwbvhWidth + s) return "wrong parent of node " + std::to_string(child);
        } else if (n.isLeaf(s)) {
          const uint32_t end = cwbvhLeafEnd([&] {
            uint64_t st = 0;
            for (uint32_t k = 0; k < kCwbvhWidth; ++k)
              if (n.isLeaf(k)) st |= 1ull << n.leafOffset(k);
            return st;
          }(), n.leafOffset(s), n.triCount);
          if (end <= n.leafOffset(s)) return "node " + std::to_string(i) + ": empty leaf";
          if (auto p = cover(n.triBase + n.leafOffset(s), end - n.leafOffset(s))) return p;
        } else {
          return "node " + std::to_string(i) + ": bad meta byte";
        }
        if (checkBoxes) {
          const Aabb& exact = t.exactBoxes[std::size_t(i) * kCwbvhWidth + s];
          if (!cwbvhChildBoxContains(n, s, exact))
            return "node " + std::to_string(i) + " slot " + std::to_string(s) +
                   ": the quantized box does not contain the exact box";
        }
      }
      if (occupied < 1) return "node " + std::to_string(i) + " has no children";
    }
  }
  for (uint32_t s = 0; s < slots; ++s)
    if (!covered[s]) return "triangle slot " + std::to_string(s) + " in no leaf";
  return std::nullopt;
}

}  // namespace tsah
