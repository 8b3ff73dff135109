#pragma once
// Insertion-based BVH optimization (Bittner, Hapala, Havran 2013) with the temporal SAH
// (Bittner & Meister 2015, Section 5).
//
// One step removes an interior node N (not the root, not a child of the root) together with its
// parent P (N's sibling takes P's place), then reinserts N's two children, the larger first, each
// where it raises the cost least; the freed N and P become their new parents. The position is found
// by branch-and-bound over the tree with a priority queue ordered by induced cost, where every cost
// is the weighted multi-frame area A(B) = sum_i (w_i / W) * area(B_i) / S_i. A step that raised the
// T-SAH cost C~^k is undone. Steps run in batches of 2% of the nodes; after each batch the frame
// costs C_i are recomputed and (k > 0) the weights w_i = C_i^k; the run stops after 3 batches
// without a reduction of C~^k.
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/optimize/leaf_collapser.hpp"

namespace tsah {

class InsertionOptimizer {
 public:
  using Selection = tsah::Selection;  // core/kinds.hpp

  // The state after one batch (batch 0: the starting tree), for progress and convergence plots.
  struct BatchRecord {
    uint32_t batch = 0;
    double cost = 0.0;          // C~^k, recomputed from scratch after the batch
    double averageCost = 0.0;   // C~^0, the mean frame cost (the paper's Figure 3 and 4)
    double elapsedSeconds = 0.0;
    uint64_t steps = 0;         // steps tried so far
    uint64_t acceptedSteps = 0; // steps kept so far (not undone)
  };

  struct Config {
    CostModel cost;
    int k = 0;  // T-SAH exponent (Eq. 3); 0 optimizes the average frame cost
    Selection selection = Selection::MetropolisHastings;
    uint64_t seed = 1;
    double batchFraction = 0.02;            // steps per batch, as a fraction of the node count
    // At least this many steps per batch: on small trees 2% is a handful of steps, and three such
    // batches without improvement would end the run long before it converged.
    uint32_t minBatchSize = 64;
    uint32_t batchesWithoutImprovement = 3; // stop after this many batches that did not lower C~^k
    // A batch "lowers" the cost when it ends below (1 - minImprovement) times the best cost so far.
    // 1e-5 ends the long tail of ever smaller gains (0.05% of the cost on Sibenik, 7x the time);
    // 0 waits for batches with no reduction at all.
    double minImprovement = 1e-5;
    double timeLimitSeconds = 0.0;          // 0: no limit
    uint32_t maxBatches = 0;                // 0: no limit
    std::function<void(const BatchRecord&)> progress;  // called after every batch
    // Polled every 32 steps and after every batch (round); once it returns true the optimizer
    // throws tsah::Cancelled. Several optimizations may run at once (SAH*, tree sets): it must be
    // cheap and safe to call from several threads (an atomic flag).
    std::function<bool()> cancelled;
  };

  struct Result {
    Bvh bvh;  // boxes for every frame of the input primitives
    std::vector<double> initialFrameCosts, finalFrameCosts;
    double initialCost = 0.0, finalCost = 0.0;  // C~^k
    std::vector<BatchRecord> history;
    uint64_t steps = 0, acceptedSteps = 0;
    double seconds = 0.0;
    bool timeLimitReached = false;
  };

  InsertionOptimizer() = default;
  explicit InsertionOptimizer(Config config);
  const Config& config() const { return config_; }

  // Optimizes a valid tree over prims (any leaf sizes; its boxes are recomputed from prims for all
  // prims.frameCount frames). Deterministic for a given seed. With `collapse`, Result::bvh is the
  // optimized tree collapsed by it: the same tree as collapse->collapse() of the tree returned
  // without it, made without a second copy of every node's boxes (memory). Result::bvh is at most
  // kMaxBvhDepth deep (limitDepth); the costs are those of the optimized tree before the collapse
  // and the depth bound.
  Result optimize(Bvh bvh, const PrimitiveBoxes& prims, const LeafCollapser* collapse = nullptr) const;

 private:
  Config config_;
};

// Throws tsah::Cancelled when config.cancelled is set and returns true (the optimizers, and the
// builders between the trees they build, call it).
void throwIfCancelled(const InsertionOptimizer::Config& config);

// The step-level machinery behind InsertionOptimizer: one tree under optimization with its cached
// multi-frame areas, frame costs and weights. Public so that tests (and experiments) can drive
// single steps and check the tree after each of them.
class InsertionSession {
 public:
  // Refits bvh to prims (all frames) and computes the frame costs and weights. Throws
  // tsah::DataError when prims does not match the tree. prims must outlive the session.
  InsertionSession(Bvh bvh, const PrimitiveBoxes& prims, const InsertionOptimizer::Config& config);
  ~InsertionSession();
  InsertionSession(InsertionSession&&) noexcept;
  InsertionSession& operator=(InsertionSession&&) noexcept;

  // An interior node that is neither the root nor a child of the root.
  bool eligible(uint32_t node) const;
  // One remove-and-reinsert step at an eligible node. Returns true when the step was kept, false
  // when it raised C~^k and was undone (the tree is then exactly as before).
  bool step(uint32_t node);
  // The next node by Metropolis-Hastings or uniform selection (per the config; batch sorting uses
  // batchSortNodes). kInvalidIndex when no node is eligible.
  uint32_t selectNode();
  // The (at most) count eligible nodes with the highest inefficiency measure
  // M = M_sum * M_min * M_area of Bittner 2013 over weighted multi-frame areas, highest first.
  std::vector<uint32_t> batchSortNodes(uint32_t count) const;
  // Recomputes every frame cost from the node boxes, the weights w_i = C_i^k and the cached
  // weighted areas.
  void refresh();
  // What the optimizer does after a batch: new weights for k > 0 (the frame costs themselves are
  // tracked exactly step by step, so k = 0 needs nothing).
  void endBatch();

  double cost() const;                        // C~^k of the current frame costs
  std::span<const double> frameCosts() const;  // C_i, kept up to date step by step
  const Bvh& bvh() const;  // materializes the tree with every node's boxes (tests, inspection)
  uint32_t nodeCount() const;
  Bvh release();  // moves the tree out; the session is unusable afterwards
  // collapser.collapse(release()), with the peak memory of the session alone.
  Bvh releaseCollapsed(const LeafCollapser& collapser);
  uint64_t steps() const;
  uint64_t acceptedSteps() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tsah
