#pragma once
// The BVH as plain data: index-based nodes with parent links, leaves holding ranges into a
// primitive (triangle) index array, and one box per representative frame for every node.
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/aabb.hpp"

namespace tsah {

inline constexpr uint32_t kInvalidIndex = 0xffffffffu;

// The deepest tree (root at depth 0) the library makes: every builder, optimizer and leaf collapse
// ends with limitDepth, so any tree it writes fits the runtimes' traversal stacks
// (kTraversalStackSize, the CUDA traversal's stack) and the wide layouts' stacks.
inline constexpr uint32_t kMaxBvhDepth = 128;

struct BvhNode {
  uint32_t parent = kInvalidIndex;  // kInvalidIndex for the root
  uint32_t left = kInvalidIndex;    // children of an interior node
  uint32_t right = kInvalidIndex;
  uint32_t primBegin = 0;  // leaf: primIds[primBegin, primBegin + primCount)
  uint32_t primCount = 0;  // > 0 exactly for leaves

  bool isLeaf() const { return primCount > 0; }
};

// Axis-aligned boxes of every primitive in every frame: boxes[frame * primCount + prim].
struct PrimitiveBoxes {
  uint32_t frameCount = 0;
  uint32_t primCount = 0;
  std::vector<Aabb> boxes;

  const Aabb& at(uint32_t frame, uint32_t prim) const {
    return boxes[std::size_t(frame) * primCount + prim];
  }
  std::span<const Aabb> frame(uint32_t f) const {
    return std::span<const Aabb>(boxes).subspan(std::size_t(f) * primCount, primCount);
  }
};

// Boxes of the triangles (3 indices each) for one frame of vertex positions (xyz floats).
void triangleBoxes(std::span<const uint32_t> indices, std::span<const float> positions,
                   std::span<Aabb> out);
// Boxes of the triangles for several frames: positions holds frameCount blocks of vertices*3 floats.
PrimitiveBoxes triangleBoxes(std::span<const uint32_t> indices, std::span<const float> positions,
                             uint32_t frameCount);

struct Bvh {
  uint32_t frameCount = 1;         // boxes per node
  uint32_t root = 0;
  std::vector<BvhNode> nodes;
  std::vector<uint32_t> primIds;   // leaf ranges index this array
  std::vector<Aabb> boxes;         // nodes.size() * frameCount, node-major

  Aabb& box(uint32_t node, uint32_t frame) { return boxes[std::size_t(node) * frameCount + frame]; }
  const Aabb& box(uint32_t node, uint32_t frame) const {
    return boxes[std::size_t(node) * frameCount + frame];
  }
  uint32_t nodeCount() const { return static_cast<uint32_t>(nodes.size()); }
  uint32_t leafCount() const;
  uint32_t primCount() const { return static_cast<uint32_t>(primIds.size()); }
  // Depth of the deepest leaf (the root has depth 0).
  uint32_t depth() const;
};

// The nodes reachable from the root, every child before its parent (the order of bottom-up passes).
std::vector<uint32_t> childrenFirstOrder(const Bvh& bvh);

// Recomputes every node box from the primitive boxes, bottom-up, for all frames of prims
// (bvh.frameCount becomes prims.frameCount).
void refit(Bvh& bvh, const PrimitiveBoxes& prims);
// The same boxes written to other storage: boxesOf(node) is where node's prims.frameCount boxes go
// (children are written before their parent and read back from there); bvh.boxes is not used.
void refitInto(const Bvh& bvh, const PrimitiveBoxes& prims, const std::function<Aabb*(uint32_t node)>& boxesOf);

// Makes the tree at most maxDepth deep by rebuilding the lowest subtrees that would be deeper as
// balanced subtrees over their leaves (split at the middle of their left-to-right order, which keeps
// neighbours together). Leaves, their primitives and every node index stay; the rebuilt interior
// nodes get new children and, when the tree has boxes, the union of their children's boxes in every
// frame, so the tree stays valid. Returns whether anything changed (never for a shallow enough tree).
// Throws tsah::ConfigError when even a balanced tree over all leaves would be deeper than maxDepth.
bool limitDepth(Bvh& bvh, uint32_t maxDepth = kMaxBvhDepth);

// Checks the tree invariants: the root has no parent, parent/child links agree, every node is
// reachable from the root exactly once (no cycles, no orphans), every primitive sits in exactly one
// leaf, leaves have primCount > 0 and interior nodes two children, and (when prims is given) every
// box contains its children's boxes and its primitives' boxes in every frame.
// Returns a description of the first violation, or nothing when the tree is valid.
std::optional<std::string> validate(const Bvh& bvh, const PrimitiveBoxes* prims = nullptr);

}  // namespace tsah
