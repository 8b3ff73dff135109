#include "tsah/layout/moving_parts.hpp"

#include "tsah/base/error.hpp"

namespace tsah {

MovingParts findMovingParts(const FlatBvh& tree, std::span<const uint32_t> indices,
                            std::span<const uint32_t> movingVertices, uint32_t vertexCount) {
  if (indices.size() != std::size_t(tree.triangleCount()) * 3)
    throw tsah::DataError("moving parts: the tree holds " + std::to_string(tree.triangleCount()) +
                          " triangles, the indices " + std::to_string(indices.size() / 3));
  std::vector<uint8_t> vertexMoves(vertexCount, 0);
  for (uint32_t v : movingVertices) {
    if (v >= vertexCount) throw tsah::DataError("moving parts: a moving vertex id is out of range");
    vertexMoves[v] = 1;
  }
  MovingParts parts;
  parts.slotMoves.resize(tree.triangleCount());
  for (uint32_t s = 0; s < tree.triangleCount(); ++s) {
    const uint32_t* tri = indices.data() + 3 * std::size_t(tree.triIndex[s]);
    for (int k = 0; k < 3; ++k)
      if (tri[k] >= vertexCount) throw tsah::DataError("moving parts: a triangle refers to a vertex out of range");
    parts.slotMoves[s] = vertexMoves[tri[0]] | vertexMoves[tri[1]] | vertexMoves[tri[2]];
    parts.movingSlots += parts.slotMoves[s];
  }
  parts.nodeMoves.assign(tree.interiorCount, 0);
  // Canonical order: every child has a larger index than its parent, so one descending pass sees
  // the children first.
  for (uint32_t i = tree.interiorCount; i-- > 0;) {
    const GpuBvhNode& node = tree.nodes[i];
    uint8_t moves = 0;
    for (int c = 0; c < 2; ++c) {
      const int32_t ref = node.childRef(c);
      if (isLeafRef(ref)) {
        for (uint32_t s = leafFirstSlot(ref); s < leafFirstSlot(ref) + node.childCount(c); ++s) moves |= parts.slotMoves[s];
      } else {
        moves |= parts.nodeMoves[uint32_t(ref)];
      }
    }
    parts.nodeMoves[i] = moves;
    parts.movingNodes += moves;
  }
  return parts;
}

}  // namespace tsah
