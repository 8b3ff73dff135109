#pragma once
// Adaptive leaf size (the paper's Section 5.4, after Bittner 2013): bottom-up, a subtree becomes one
// leaf when cI * j_N * A(N) is not more than the cost of keeping it as it is, where A is the
// T-SAH-weighted multi-frame area A(B) = sum_i (w_i / W) * area(B_i) / S_i over the frames stored in
// the tree and w_i = C_i^k are the frame weights of the whole tree.
#include <cstdint>
#include <functional>
#include <span>

#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"

namespace tsah {

// A binary tree with boxes of every frame, as the collapser reads it: a Bvh (CollapseSource::of),
// or an optimizer's own storage, so that collapsing an optimized tree needs no second copy of every
// node's boxes. Node ids are [0, nodeCount); nodes not reachable from the root count in the cost of
// the uncollapsed tree as they do in frameCosts(Bvh). Both functions are called from several
// threads at once (subtrees of a large tree are collapsed in parallel): they must only read.
struct CollapseSource {
  uint32_t frameCount = 0;
  uint32_t nodeCount = 0;
  uint32_t root = 0;
  std::span<const uint32_t> primIds;
  std::function<BvhNode(uint32_t node)> node;            // links and primitive range
  std::function<void(uint32_t node, Aabb* out)> boxes;  // frameCount boxes of the node

  // A view of bvh (which must outlive it).
  static CollapseSource of(const Bvh& bvh);
};

class LeafCollapser {
 public:
  // The objective: cT, cI, the T-SAH exponent of the frame weights and the largest leaf.
  using Config = Objective;

  LeafCollapser() = default;
  explicit LeafCollapser(Config config);
  const Config& config() const { return config_; }

  // Returns the collapsed tree, compacted: nodes renumbered depth-first (root 0, the two children
  // of a node adjacent) and primIds reordered so that every leaf's range is contiguous in that
  // order. Never raises the T-SAH cost C~^k over the tree's frames: for k = 0 the greedy decisions
  // are exact; for k > 0, where lowering one frame's cost can raise C~^k through the weights, a
  // result that would raise it is retried with the new weights and otherwise not collapsed.
  Bvh collapse(const Bvh& bvh) const;

  // The same collapse of a tree given as a source, without boxes (frameCount set, boxes empty):
  // the caller fills them with refit(result, prims) once the source is gone. That gives exactly the
  // boxes collapse() copies when the source's boxes are the unions of their primitives' boxes (an
  // optimizer's tree). Peak memory: the result's topology and one byte per source node.
  Bvh collapseTopology(const CollapseSource& source) const;

  // The tree renumbered as described above; nodes flagged in `asLeaf` (indexed by node, may be
  // empty) become leaves holding every primitive below them.
  static Bvh compact(const Bvh& bvh, std::span<const uint8_t> asLeaf = {});

 private:
  // The collapse decisions (one flag per source node) with frame weights `weights`.
  std::vector<uint8_t> leafFlags(const CollapseSource& source, std::span<const double> weights) const;
  // The collapsed topology; origin[i] is the source node of output node i.
  Bvh collapsedTopology(const CollapseSource& source, std::vector<uint32_t>& origin) const;
  Config config_;
};

}  // namespace tsah
