#pragma once
// Which parts of a tree ever move. A triangle moves when any of its vertices moves; a leaf or an
// interior node moves when any triangle below it does. A scene's static environment (vertices an
// anim::Animation stores once, as rest positions) never moves, so after one full refit the boxes of
// its subtrees and its Woop triangles stay valid: the per-frame refit recomputes only the moving
// parts (GpuRuntime::updateAt; docs/cuda-runtime.md#static-subtrees).
#include <cstdint>
#include <span>
#include <vector>

#include "tsah/layout/flat_bvh.hpp"

namespace tsah {

struct MovingParts {
  std::vector<uint8_t> nodeMoves;  // per interior node of one frame block: 1 when its subtree moves
  std::vector<uint8_t> slotMoves;  // per slot: 1 when the slot's triangle moves
  uint32_t movingSlots = 0;        // how many slots move
  uint32_t movingNodes = 0;        // how many interior nodes move
  bool rootMoves() const { return movingSlots > 0; }
};

// The moving parts of `tree` (its topology; any frame block) for the triangles `indices` (3 vertex
// ids per triangle id) when exactly the vertices `movingVertices` (ascending ids, each <
// vertexCount) move. The tree must be valid (validateFlatBvh) and match the indices.
MovingParts findMovingParts(const FlatBvh& tree, std::span<const uint32_t> indices,
                            std::span<const uint32_t> movingVertices, uint32_t vertexCount);

}  // namespace tsah
