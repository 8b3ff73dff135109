#pragma once
// A tree's data for the bottom-up refit (kernels.hpp's launchRefit and its batches): the parents of
// the interior nodes and one record per leaf, shared by the flat and the two-level runtimes.
#include <cstdint>
#include <vector>

#include "device_types.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah::cuda::detail {

struct RefitTopology {
  std::vector<uint32_t> parent;    // per interior node: its parent's slot (node * 2 + side), kNoParent at the root
  std::vector<LeafRecord> leaves;  // a tree that is one leaf: one record without a parent
};

inline RefitTopology refitTopology(const FlatBvh& tree) {
  RefitTopology r;
  r.parent.assign(tree.interiorCount, kNoParent);
  r.leaves.reserve(tree.leafCount);
  if (tree.interiorCount == 0) {
    r.leaves.push_back({kNoParent, 0, tree.rootCount});
    return r;
  }
  for (uint32_t i = 0; i < tree.interiorCount; ++i) {
    const GpuBvhNode& n = tree.nodes[i];
    for (int c = 0; c < 2; ++c) {
      const int32_t ref = n.childRef(c);
      const uint32_t slot = (i << 1) | uint32_t(c);
      if (isLeafRef(ref))
        r.leaves.push_back({slot, leafFirstSlot(ref), n.childCount(c)});
      else
        r.parent[uint32_t(ref)] = slot;
    }
  }
  return r;
}

}  // namespace tsah::cuda::detail
