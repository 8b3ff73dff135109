#pragma once
// The CPU two-level runtime's top level in a wide layout (BLAS in bvh4 or bvh8): the binary TLAS's
// topology collapsed into N-wide nodes whose leaf children are single instances, traced by the
// visitor kernels of wide_visit.hpp. One SIMD node test then tests up to N instance boxes at once,
// where the binary loop tests two boxes per node and then each instance's box of a leaf one by one.
#include <cstdint>
#include <span>
#include <vector>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/wide_layout.hpp"

namespace tsah::detail {

template <uint32_t N>
class WideTlas {
 public:
  // The topology of `tlas` (canonical form, slots holding instance ids): from its root, each wide
  // node opens the binary subtree below it greedily, largest box (surface area in instanceBoxes)
  // first, until it holds N children; a binary leaf of several instances opens into halves of its
  // slot range, so every instance ends as a leaf child of its own (ref = makeLeafRef(instance),
  // count 1). Call refit before tracing.
  WideTlas(const FlatBvh& tlas, std::span<const Aabb> instanceBoxes);
  // Every node's child boxes bottom-up: a leaf child's is its instance's box.
  void refit(std::span<const Aabb> instanceBoxes);
  // The nodes as the visitor kernels read them (no triangles).
  WideView<N> view() const;
  std::size_t bytes() const { return nodes_.size() * sizeof(WideSoaNode<N>) + used_.size(); }

 private:
  struct Candidate;
  int32_t build(const Candidate& c, const FlatBvh& tlas, std::span<const Aabb> instanceBoxes);

  std::vector<WideSoaNode<N>> nodes_;  // node 0 the root (when it is not a leaf); children after parents
  std::vector<uint8_t> used_;          // per node: its used child slots (the first ones)
  int32_t rootRef_ = makeLeafRef(0);
  uint32_t rootCount_ = 0;
  Aabb rootBox_;
};

extern template class WideTlas<4>;
extern template class WideTlas<8>;

}  // namespace tsah::detail
