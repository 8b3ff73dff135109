#pragma once
// A canonical flat tree split for a refit by blocks of GPU threads, each block walking its part in
// shared memory (the two-level runtime's BLAS and TLAS refits, cuda_kernels/src/refit_walk.cuh):
// subtrees of at most maxLeaves leaves (the "parts", refitted concurrently, one block each), then
// the nodes above them (the "top", refitted last, over the parts' root boxes and its own leaves).
// A walk through global memory waits for a round trip to L2 per level; a block's walk waits for
// shared memory, so a part costs a leaf load plus its depth in cheap steps.
#include <cstdint>
#include <vector>

namespace tsah {

struct FlatBvh;  // tsah/layout/flat_bvh.hpp

// A part's walk ends at a slot of this value: its root's box is the part's result.
inline constexpr uint32_t kPartExitSlot = 0xffffffffu;
// An item whose count is this is not a leaf: its box is the result of subtree part `first`.
inline constexpr uint32_t kPartEntry = 0xffffffffu;

// Where a box enters a part's walk: parentSlot is the local node (index within the part) times two
// plus the side it fills, or kPartExitSlot when the item is the part's whole tree (a root leaf).
// A leaf item covers slots [first, first + count) of the tree; an entry item (count == kPartEntry)
// is the root box of subtree part `first`.
struct RefitPartItem {
  uint32_t parentSlot = kPartExitSlot;
  uint32_t first = 0;
  uint32_t count = 0;
};

// Local nodes [firstNode, firstNode + nodeCount) of RefitParts::parentSlot / globalNode, items
// [firstItem, firstItem + itemCount) of RefitParts::items. A subtree part (or a tree that is one
// part) owns the consecutive slots [firstSlot, firstSlot + slotCount) of its leaves; the top's
// leaves are scattered (slotCount 0).
struct RefitPart {
  uint32_t firstNode = 0, nodeCount = 0, firstItem = 0, itemCount = 0;
  uint32_t firstSlot = 0, slotCount = 0;
};

struct RefitParts {
  std::vector<RefitPart> parts;        // the subtrees in depth-first order, then the top (hasTop)
  bool hasTop = false;                 // false: one part, the whole tree
  std::vector<uint32_t> parentSlot;    // per local node: its parent's local slot, or kPartExitSlot
  std::vector<uint32_t> globalNode;    // per local node: its index in the tree
  std::vector<RefitPartItem> items;    // in slot order within each part

  uint32_t subtreeCount() const { return uint32_t(parts.size()) - (hasTop ? 1u : 0u); }
  uint32_t maxNodeCount() const;       // the most local nodes of one part (its shared memory)
};

// Splits `tree` (canonical, validated) into subtrees of at most maxLeaves leaves and the top above
// them (there is at least one subtree); a tree of at most maxLeaves leaves is one part. Throws
// tsah::ConfigError for maxLeaves < 2.
RefitParts splitForBlockRefit(const FlatBvh& tree, uint32_t maxLeaves);

}  // namespace tsah
