#pragma once
// Binned SAH builder (Wald 2007): at every node the primitive centroids are binned on each axis and
// the best of the bin boundaries is taken by the surface area heuristic. Fast enough to rebuild a
// tree every frame: the per-frame rebuild baseline of the CPU runtime (`tsah trace --rebuild binned`).
//
// Multithreaded on the caller's TBB arena: the top of the tree is built with parallel bounds,
// binning and a stable partition (fixed chunks merged in order), every subtree below
// `parallelThreshold` primitives is a task of its own, and the subtrees are copied into the tree
// concurrently, each to its place in task order. The result does not depend on the number of threads.
#include <cstdint>
#include <span>

#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"

namespace tsah {

class BinnedSahBuilder {
 public:
  struct Config {
    CostModel cost;                       // cT, cI of the split/leaf decision
    uint32_t binCount = 16;               // bins per axis, 2..256
    uint32_t maxLeafSize = 8;             // ranges larger than this are always split
    uint32_t parallelThreshold = 4096;    // subtrees smaller than this are built by one task
  };

  BinnedSahBuilder() = default;
  explicit BinnedSahBuilder(Config config) : config_(config) {}
  const Config& config() const { return config_; }

  // Builds a tree over one frame of primitive boxes (indexed by primitive id); frameCount = 1,
  // the root is node 0, the two children of a node are adjacent, each leaf holds 1..maxLeafSize
  // primitives. Throws tsah::ConfigError for an invalid configuration, tsah::DataError for an empty
  // or non-finite box or more primitives than 32-bit indices address. An empty input gives an
  // empty tree.
  Bvh build(std::span<const Aabb> primBoxes) const;

 private:
  Config config_;
};

}  // namespace tsah
