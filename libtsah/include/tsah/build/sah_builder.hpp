#pragma once
// Full-sweep SAH builder (the paper's initial tree, Section 3): centroids are sorted once per axis,
// the three orders are kept partitioned stably, and every split position on every axis is
// evaluated with the surface area heuristic. O(n log n) sort plus O(n) work per tree level.
#include <cstdint>
#include <span>

#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"

namespace tsah {

class SweepSahBuilder {
 public:
  struct Config {
    // cT and cI decide whether a range small enough (maxLeafSize) becomes a leaf.
    CostModel cost;
    // 1 (the default): one primitive per leaf, the input the optimizer needs. Larger: a range of at
    // most this many primitives becomes a leaf when that is not more expensive than splitting it.
    uint32_t maxLeafSize = 1;
  };

  SweepSahBuilder() = default;
  explicit SweepSahBuilder(Config config) : config_(config) {}
  const Config& config() const { return config_; }

  // Builds a tree over one frame of primitive boxes (indexed by primitive id). The result holds one
  // box per node (frameCount = 1); refit() adds further frames. Nodes are numbered so that the root
  // is 0 and the two children of a node are adjacent. Throws tsah::DataError for a box with a
  // non-finite coordinate or more primitives than 32-bit node indices can address.
  Bvh build(std::span<const Aabb> primBoxes) const;

 private:
  Config config_;
};

}  // namespace tsah
