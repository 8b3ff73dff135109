#pragma once
// Adaptive leaf size (the paper's Section 5.4, after Bittner 2013): bottom-up, a subtree becomes one
// leaf when cI * j_N * A(N) is not more than the cost of keeping it as it is, where A is the
// T-SAH-weighted multi-frame area A(B) = sum_i (w_i / W) * area(B_i) / S_i over the frames stored in
// the tree and w_i = C_i^k are the frame weights of the whole tree.
#include <cstdint>
#include <span>

#include "tsah/bvh.hpp"
#include "tsah/cost.hpp"

namespace tsah {

class LeafCollapser {
 public:
  struct Config {
    CostModel cost;
    uint32_t maxLeafSize = 8;  // a collapsed leaf holds at most this many primitives
    int k = 0;                 // T-SAH exponent of the frame weights
  };

  LeafCollapser() = default;
  explicit LeafCollapser(Config config);
  const Config& config() const { return config_; }

  // Returns the collapsed tree, compacted: nodes renumbered depth-first (root 0, the two children
  // of a node adjacent) and primIds reordered so that every leaf's range is contiguous in that
  // order. Never raises the T-SAH cost C~^k over the tree's frames: for k = 0 the greedy decisions
  // are exact; for k > 0, where lowering one frame's cost can raise C~^k through the weights, a
  // result that would raise it is retried with the new weights and otherwise not collapsed.
  Bvh collapse(const Bvh& bvh) const;

  // The tree renumbered as described above; nodes flagged in `asLeaf` (indexed by node, may be
  // empty) become leaves holding every primitive below them.
  static Bvh compact(const Bvh& bvh, std::span<const uint8_t> asLeaf = {});

 private:
  Bvh collapseWithWeights(const Bvh& bvh, std::span<const double> weights) const;
  Config config_;
};

}  // namespace tsah
