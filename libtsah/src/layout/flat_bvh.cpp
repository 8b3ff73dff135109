#include "tsah/layout/flat_bvh.hpp"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>

#include "core/parallel_tree.hpp"
#include "tsah/base/error.hpp"

namespace tsah {

namespace {

bool finiteNonEmpty(const Aabb& b) {
  const float v[6] = {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z};
  for (float x : v)
    if (!std::isfinite(x)) return false;
  return b.lo.x <= b.hi.x && b.lo.y <= b.hi.y && b.lo.z <= b.hi.z;
}

std::string str(uint64_t v) { return std::to_string(v); }

// The flat layout's pre-order walk, left first: an interior node takes the next interior index
// when it is reached, a leaf the next primitives. So a subtree's place follows from the sizes of
// the subtrees before it, and the top levels' subtrees are measured, then written, in parallel.
class Flattening {
 public:
  Flattening(const Bvh& bvh, FlatBvh& flat)
      : bvh_(bvh), flat_(flat), levels_(detail::parallelTreeLevels(bvh.nodes.size())),
        sizes_(detail::topLevelSlots(levels_)) {}

  void run() {
    measure();
    flat_.depth = place({bvh_.root, kInvalidIndex, 0, 0}, 0, 0, levels_, 1);
  }

 private:
  // Each walk entry names a Bvh node and where its reference goes: the parent's flat index and
  // child slot (parent kInvalidIndex for the root).
  struct Item {
    uint32_t node, parent, depth;
    int side;
  };
  struct Size {
    uint32_t interiors = 0, prims = 0;
  };

  // The subtree's interior nodes and primitives; the top levels' kept in sizes_ at their heap
  // position (root 1, children 2p and 2p + 1).
  void measure() {
    detail::reduceTree<Size>(
        bvh_.root, [&](uint32_t n) { return detail::shapeOf(bvh_, n); },
        [&](uint32_t n) { return Size{0, bvh_.nodes[n].primCount}; },
        [](uint32_t, Size left, Size right) {
          return Size{1 + left.interiors + right.interiors, left.prims + right.prims};
        },
        levels_, &sizes_);
  }

  // Writes `item`'s subtree with its interior nodes from index nextInterior and its primitives
  // from nextPrim; returns the subtree's deepest depth.
  uint32_t place(const Item& item, uint32_t nextInterior, uint32_t nextPrim, int levels, std::size_t position) {
    const BvhNode& node = bvh_.nodes[item.node];
    if (!node.isLeaf() && levels > 0) {
      const uint32_t index = nextInterior;
      reference(item, int32_t(index), 0);
      const Size left = sizes_[2 * position];
      uint32_t leftDepth = 0, rightDepth = 0;
      tbb::parallel_invoke(
          [&] { leftDepth = place({node.left, index, item.depth + 1, 0}, index + 1, nextPrim, levels - 1, 2 * position); },
          [&] {
            rightDepth = place({node.right, index, item.depth + 1, 1}, index + 1 + left.interiors, nextPrim + left.prims,
                               levels - 1, 2 * position + 1);
          });
      return std::max(leftDepth, rightDepth);
    }
    uint32_t depth = 0;
    std::vector<Item> stack{item};
    while (!stack.empty()) {
      const Item top = stack.back();
      stack.pop_back();
      const BvhNode& n = bvh_.nodes[top.node];
      depth = std::max(depth, top.depth);
      if (n.isLeaf()) {
        reference(top, makeLeafRef(nextPrim), n.primCount);
        for (uint32_t i = 0; i < n.primCount; ++i) flat_.triIndex[nextPrim++] = bvh_.primIds[n.primBegin + i];
      } else {
        const uint32_t index = nextInterior++;
        reference(top, int32_t(index), 0);
        stack.push_back({n.right, index, top.depth + 1, 1});
        stack.push_back({n.left, index, top.depth + 1, 0});
      }
    }
    return depth;
  }

  // The reference to `item`'s node (and its box) in its parent, in every frame.
  void reference(const Item& item, int32_t ref, uint32_t count) {
    if (item.parent == kInvalidIndex) {
      flat_.rootRef = ref;
      flat_.rootCount = count;
      return;
    }
    for (uint32_t f = 0; f < flat_.frameCount; ++f) {
      GpuBvhNode& parent = flat_.frameNodes(f)[item.parent];
      parent.setChildBox(item.side, bvh_.box(item.node, f));
      (item.side == 0 ? parent.ref0 : parent.ref1) = ref;
      (item.side == 0 ? parent.count0 : parent.count1) = count;
    }
  }

  const Bvh& bvh_;
  FlatBvh& flat_;
  int levels_;
  std::vector<Size> sizes_;
};

}  // namespace

FlatBvh flattenBvh(const Bvh& bvh) {
  if (bvh.nodes.empty() || bvh.primIds.empty()) throw tsah::DataError("cannot flatten an empty BVH");
  if (auto problem = validate(bvh)) throw tsah::DataError("cannot flatten an invalid BVH: " + *problem);
  if (bvh.primIds.size() > kMaxGpuTriangles) throw tsah::DataError("BVH has too many primitives");

  FlatBvh flat;
  flat.frameCount = bvh.frameCount;
  const uint32_t leafCount = bvh.leafCount();
  flat.leafCount = leafCount;
  flat.interiorCount = bvh.nodeCount() - leafCount;
  flat.nodes.resize(std::size_t(flat.frameCount) * flat.interiorCount);
  flat.rootBoxes.resize(flat.frameCount);
  flat.triIndex.resize(bvh.primIds.size());
  for (uint32_t f = 0; f < flat.frameCount; ++f) flat.rootBoxes[f] = bvh.box(bvh.root, f);
  Flattening(bvh, flat).run();
  return flat;
}

Bvh unflattenBvh(const FlatBvh& flat) {
  Bvh bvh;
  bvh.frameCount = flat.frameCount;
  bvh.root = 0;
  bvh.primIds = flat.triIndex;
  const std::size_t nodeCount = std::size_t(flat.interiorCount) + flat.leafCount;
  bvh.nodes.resize(nodeCount);
  bvh.boxes.resize(nodeCount * flat.frameCount);
  for (uint32_t f = 0; f < flat.frameCount; ++f) bvh.box(0, f) = flat.rootBoxes[f];
  uint32_t nextLeaf = flat.interiorCount;

  // Bvh index of a child reference; leaves get the next free index in depth-first order, which
  // the pre-order numbering of interior nodes makes the same order as the traversal below.
  auto place = [&](int32_t ref, uint32_t count, uint32_t parent) {
    uint32_t n;
    if (isLeafRef(ref)) {
      n = nextLeaf++;
      bvh.nodes[n].primBegin = leafFirstSlot(ref);
      bvh.nodes[n].primCount = count;
    } else {
      n = static_cast<uint32_t>(ref);
    }
    bvh.nodes[n].parent = parent;
    return n;
  };
  if (flat.interiorCount == 0) {
    place(flat.rootRef, flat.rootCount, kInvalidIndex);
    return bvh;
  }
  // Visit interior nodes in pre-order so leaves are numbered in depth-first order.
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    const GpuBvhNode& node0 = flat.frameNodes(0)[i];
    const uint32_t left = place(node0.ref0, node0.count0, i);
    const uint32_t right = place(node0.ref1, node0.count1, i);
    bvh.nodes[i].left = left;
    bvh.nodes[i].right = right;
    for (uint32_t f = 0; f < flat.frameCount; ++f) {
      const GpuBvhNode& node = flat.frameNodes(f)[i];
      bvh.box(left, f) = node.childBox(0);
      bvh.box(right, f) = node.childBox(1);
    }
    if (!isLeafRef(node0.ref1)) stack.push_back(right);
    if (!isLeafRef(node0.ref0)) stack.push_back(left);
  }
  return bvh;
}

std::optional<std::string> validateFlatBvh(const FlatBvh& flat) {
  const uint64_t triangles = flat.triIndex.size();
  if (triangles == 0) return "the tree holds no triangles";
  if (triangles > kMaxGpuTriangles) return "too many triangles (" + str(triangles) + ")";
  if (flat.frameCount == 0) return "no box sets (frame count 0)";
  if (flat.nodes.size() != uint64_t(flat.frameCount) * flat.interiorCount)
    return "node array size does not match interior nodes x frames";
  if (flat.rootBoxes.size() != flat.frameCount) return "root box count does not match frames";
  if (flat.interiorCount == 0) {
    if (!isLeafRef(flat.rootRef) || leafFirstSlot(flat.rootRef) != 0 || flat.rootCount != triangles ||
        flat.leafCount != 1 || flat.depth != 0)
      return "a tree without interior nodes must be one leaf holding every triangle";
  } else {
    if (flat.rootRef != 0 || flat.rootCount != 0) return "the root must be interior node 0";
    if (uint64_t(flat.leafCount) != uint64_t(flat.interiorCount) + 1)
      return "a binary tree with " + str(flat.interiorCount) + " interior nodes has " +
             str(uint64_t(flat.interiorCount) + 1) + " leaves, not " + str(flat.leafCount);
  }
  if (flat.leafCount > triangles) return "more leaves than triangles";

  // triIndex must be a permutation of [0, triangles).
  {
    std::vector<uint8_t> seen(triangles, 0);
    for (uint64_t s = 0; s < triangles; ++s) {
      const uint32_t t = flat.triIndex[s];
      if (t >= triangles) return "slot " + str(s) + " holds triangle " + str(t) + ", out of range";
      if (seen[t]) return "triangle " + str(t) + " appears more than once in the index array";
      seen[t] = 1;
    }
  }

  for (uint32_t f = 0; f < flat.frameCount; ++f)
    if (!finiteNonEmpty(flat.rootBoxes[f])) return "root box of frame " + str(f) + " is empty or not finite";

  // Walk in pre-order, expecting exactly the canonical numbering: this proves the graph is a tree
  // rooted at node 0 (each interior node is visited once, in order) and that leaves partition the
  // slots. Every pop advances a counter bounded by the array sizes, so a hostile file cannot loop.
  struct Item {
    int32_t ref;
    uint32_t count, depth, parent;
    int side;
  };
  std::vector<Item> stack{{flat.rootRef, flat.rootCount, 0, kInvalidIndex, 0}};
  uint64_t nextInterior = 0, nextSlot = 0, leaves = 0;
  uint32_t depth = 0;
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    depth = std::max(depth, item.depth);
    // The box of this subtree in each frame (the parent's child box, or the root box).
    auto boxOf = [&](uint32_t f) {
      return item.parent == kInvalidIndex ? flat.rootBoxes[f]
                                          : flat.frameNodes(f)[item.parent].childBox(item.side);
    };
    if (isLeafRef(item.ref)) {
      if (leafFirstSlot(item.ref) != nextSlot)
        return "leaf starts at slot " + str(leafFirstSlot(item.ref)) + ", expected " + str(nextSlot) +
               " (leaves must cover the index array in depth-first order)";
      if (item.count == 0) return "leaf at slot " + str(nextSlot) + " holds no triangles";
      if (item.count > triangles - nextSlot) return "leaf at slot " + str(nextSlot) + " runs past the index array";
      nextSlot += item.count;
      ++leaves;
      continue;
    }
    if (item.count != 0) return "interior reference " + str(uint32_t(item.ref)) + " has a leaf count";
    if (uint64_t(item.ref) != nextInterior)
      return "node reference " + str(uint32_t(item.ref)) + " where pre-order expects " + str(nextInterior) +
             " (out of range, shared, cyclic or not in depth-first order)";
    if (nextInterior >= flat.interiorCount)
      return "node reference " + str(uint32_t(item.ref)) + " out of range";
    const uint32_t i = static_cast<uint32_t>(nextInterior++);
    const GpuBvhNode& node0 = flat.frameNodes(0)[i];
    for (uint32_t f = 0; f < flat.frameCount; ++f) {
      const GpuBvhNode& node = flat.frameNodes(f)[i];
      if (f > 0 && (node.ref0 != node0.ref0 || node.ref1 != node0.ref1 || node.count0 != node0.count0 ||
                    node.count1 != node0.count1))
        return "node " + str(i) + " has different children in frame " + str(f);
      const Aabb parentBox = boxOf(f);
      for (int c = 0; c < 2; ++c) {
        const Aabb b = node.childBox(c);
        if (!finiteNonEmpty(b))
          return "node " + str(i) + " child " + str(uint32_t(c)) + " box is empty or not finite in frame " + str(f);
        if (!parentBox.contains(b))
          return "node " + str(i) + " child " + str(uint32_t(c)) + " box lies outside its parent's box in frame " +
                 str(f);
      }
    }
    stack.push_back({node0.ref1, node0.count1, item.depth + 1, i, 1});
    stack.push_back({node0.ref0, node0.count0, item.depth + 1, i, 0});
  }
  if (nextInterior != flat.interiorCount)
    return str(flat.interiorCount - nextInterior) + " interior nodes are not reachable from the root";
  if (nextSlot != triangles) return "leaves cover " + str(nextSlot) + " of " + str(triangles) + " slots";
  if (leaves != flat.leafCount) return "found " + str(leaves) + " leaves, the header says " + str(flat.leafCount);
  if (depth != flat.depth) return "tree depth is " + str(depth) + ", the header says " + str(flat.depth);
  return std::nullopt;
}

std::vector<uint32_t> subtreeEnds(const FlatBvh& flat) {
  // In pre-order a subtree ends where its right child's subtree ends (or right after the node
  // when the right child is a leaf and the left too). Children have larger indices: go backwards.
  std::vector<uint32_t> end(flat.interiorCount);
  for (uint32_t i = flat.interiorCount; i-- > 0;) {
    const GpuBvhNode& n = flat.frameNodes(0)[i];
    uint32_t e = i + 1;
    if (!isLeafRef(n.ref1)) e = end[uint32_t(n.ref1)];
    else if (!isLeafRef(n.ref0)) e = end[uint32_t(n.ref0)];
    end[i] = e;
  }
  return end;
}

FlatBvh runtimeTopology(const FlatBvh& tree, uint32_t triangles, uint32_t maxDepth, const std::string& who) {
  if (tree.triangleCount() != triangles)
    throw tsah::DataError(who + ": the tree holds " + std::to_string(tree.triangleCount()) +
                          " triangles, the animation " + std::to_string(triangles));
  FlatBvh one;
  one.frameCount = 1;
  one.interiorCount = tree.interiorCount;
  one.leafCount = tree.leafCount;
  one.depth = tree.depth;
  one.rootRef = tree.rootRef;
  one.rootCount = tree.rootCount;
  const auto block = tree.frameNodes(0);
  one.nodes.assign(block.begin(), block.end());
  one.rootBoxes = {tree.rootBoxes.empty() ? Aabb{} : tree.rootBoxes[0]};
  one.triIndex = tree.triIndex;
  if (auto problem = validateFlatBvh(one)) throw tsah::DataError(who + ": invalid tree: " + *problem);
  if (one.depth > maxDepth)
    throw tsah::DataError(who + ": tree depth " + std::to_string(one.depth) + " exceeds the traversal stack of " +
                          std::to_string(maxDepth));
  return one;
}

std::vector<uint32_t> slotVertexIndices(std::span<const uint32_t> triIndex, std::span<const uint32_t> indices,
                                        const std::string& who) {
  std::vector<uint32_t> out(3 * triIndex.size());
  for (std::size_t s = 0; s < triIndex.size(); ++s) {
    if (triIndex[s] >= indices.size() / 3)
      throw tsah::DataError(who + ": triangle " + std::to_string(triIndex[s]) + " is past the " +
                            std::to_string(indices.size() / 3) + " triangles of the index array");
    for (int k = 0; k < 3; ++k) out[3 * s + k] = indices[3 * std::size_t(triIndex[s]) + k];
  }
  return out;
}

}  // namespace tsah
