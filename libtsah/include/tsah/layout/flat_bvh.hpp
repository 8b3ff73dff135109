#pragma once
// The BVH in its GPU-ready form (GpuBvhNode arrays, see gpu_layout.hpp) and the conversions from
// and to tsah::Bvh. This is the node array of the .tbvh file and what the runtimes traverse.
//
// Canonical order (required by the file format, relied upon by refit): interior nodes are numbered
// in depth-first pre-order, left child first, so node 0 is the root, every child has a larger index
// than its parent, and the interior nodes of a subtree rooted at i are exactly [i, subtreeEnd(i)).
// Leaves own consecutive slot ranges of triIndex in the same depth-first order.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/layout/gpu_layout.hpp"

namespace tsah {

struct FlatBvh {
  uint32_t frameCount = 1;                 // box sets: one node block per frame
  uint32_t interiorCount = 0;              // interior nodes per block
  uint32_t leafCount = 0;
  uint32_t depth = 0;                      // depth of the deepest leaf (root depth 0)
  int32_t rootRef = makeLeafRef(0);        // the root as a child reference (a leaf when interiorCount == 0)
  uint32_t rootCount = 0;                  // triangles of the root when it is a leaf, else 0
  std::vector<GpuBvhNode> nodes;           // frameCount blocks of interiorCount nodes, frame-major
  std::vector<Aabb> rootBoxes;             // the root's box in each frame
  std::vector<uint32_t> triIndex;          // slot -> original triangle id (a permutation)

  uint32_t triangleCount() const { return static_cast<uint32_t>(triIndex.size()); }
  std::span<GpuBvhNode> frameNodes(uint32_t f) {
    return std::span<GpuBvhNode>(nodes).subspan(std::size_t(f) * interiorCount, interiorCount);
  }
  std::span<const GpuBvhNode> frameNodes(uint32_t f) const {
    return std::span<const GpuBvhNode>(nodes).subspan(std::size_t(f) * interiorCount, interiorCount);
  }
};

// Converts a valid Bvh (see tsah::validate) with at least one primitive into canonical flat form,
// keeping every frame's boxes. Throws tsah::DataError when the tree is empty or invalid.
FlatBvh flattenBvh(const Bvh& bvh);

// The inverse: interior node i becomes Bvh node i, leaves follow in depth-first order, primIds is
// triIndex. The input must satisfy validateFlatBvh.
Bvh unflattenBvh(const FlatBvh& flat);

// Checks every structural rule of the canonical form: node references in range and in pre-order
// (so the graph is a tree rooted at node 0), leaf slot ranges consecutive and covering all slots,
// triIndex a permutation, equal topology in every frame block, depth as stated, boxes finite and
// non-empty with every child box inside its parent's box. Returns the first violation.
// Never allocates more than O(nodes + triangles) and never loops more than that.
std::optional<std::string> validateFlatBvh(const FlatBvh& flat);

// What a runtime (CPU or GPU) keeps of a tree it refits every frame: the structure with frame 0's
// boxes only (each update recomputes them). Throws tsah::DataError, the message starting with `who`
// ("runtime: ..."), unless the tree holds `triangles` triangles, is valid and is at most
// `maxDepth` deep (the traversal stack).
FlatBvh runtimeTopology(const FlatBvh& tree, uint32_t triangles, uint32_t maxDepth, const std::string& who);

// The one step of every binary refit: interior node i's two child boxes, a leaf child's from
// leafBox(firstSlot, count), an interior child's the union of that child's (already refitted) boxes.
template <class LeafBox>
void refitFlatNode(std::span<GpuBvhNode> nodes, uint32_t i, const LeafBox& leafBox) {
  GpuBvhNode& node = nodes[i];
  for (int c = 0; c < 2; ++c) {
    const int32_t ref = node.childRef(c);
    node.setChildBox(c, isLeafRef(ref) ? leafBox(leafFirstSlot(ref), node.childCount(c))
                                       : nodes[static_cast<uint32_t>(ref)].bounds());
  }
}

// Frame 0 of the tree refitted bottom-up on one thread (canonical order: every child after its
// parent), root box included.
template <class LeafBox>
void refitFlat(FlatBvh& flat, const LeafBox& leafBox) {
  if (flat.interiorCount == 0) {
    flat.rootBoxes[0] = leafBox(0u, flat.rootCount);
    return;
  }
  const std::span<GpuBvhNode> nodes = flat.frameNodes(0);
  for (uint32_t i = flat.interiorCount; i-- > 0;) refitFlatNode(nodes, i, leafBox);
  flat.rootBoxes[0] = nodes[0].bounds();
}

// For each interior node i, one past the last interior node of its subtree (canonical order).
std::vector<uint32_t> subtreeEnds(const FlatBvh& flat);

// The vertex indices of each slot's triangle, 3 per slot (indices[3 * triIndex[s] + k]), so that a
// refit streams them in slot order instead of gathering indices[3 * triIndex[s]] (a cache miss per
// triangle). Throws tsah::DataError, the message starting with `who`, for a triangle id past `indices`.
std::vector<uint32_t> slotVertexIndices(std::span<const uint32_t> triIndex, std::span<const uint32_t> indices,
                                        const std::string& who);

}  // namespace tsah
