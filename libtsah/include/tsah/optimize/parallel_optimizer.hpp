#pragma once
// Parallel reinsertion with the temporal SAH (after Meister & Bittner, "Parallel Reinsertion for
// Bounding Volume Hierarchy Optimization", EG 2018), on all CPU cores with TBB.
//
// One move takes a node L (not the root, not a child of the root) out of the tree together with its
// parent P (L's sibling S takes P's place) and puts it back as the sibling of another node X, with
// P as their new parent. The optimizer works in rounds against the tree as it stands:
//   1. candidates: a seeded, thread-independent sample of the eligible nodes;
//   2. search (parallel): for each candidate the X that lowers the cost most, found without
//      removing anything: walk up from L, tracking how much every ancestor shrinks without L, and
//      search each ancestor's other subtree by branch-and-bound, every cost a weighted multi-frame
//      area A (tsah/cost_terms.hpp, the same as the sequential optimizer's);
//   3. conflicts: a move touches L, P, S, X, the path between them and their lowest common ancestor;
//      each node goes to the move of highest priority (gain, then node index); a move that owns all
//      of its nodes wins. Winners touch disjoint nodes, so their cost changes add up exactly;
//   4. acceptance: the winners' exact per-frame area changes, in priority order, each kept only when
//      it lowers C~^k (for k > 0 the weights are an approximation, as in the sequential optimizer);
//   5. apply and refit the touched paths for every representative frame (parallel);
//   6. after the round: new frame weights for k > 0.
// Rounds are focused: a node whose last search found nothing is searched again only after a move
// touched it or one of its nearest ancestors. The run stops after `batchesWithoutImprovement` rounds that
// did not lower C~^k by the relative `minImprovement` (the sequential optimizer's rule, with rounds
// for batches) followed by one full round that did not either. Results depend on the seed only, not
// on the thread count.
//
// Memory: interior nodes hold one box per frame; leaves read the caller's primitive boxes, which
// must outlive the optimization.
#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/optimize/leaf_collapser.hpp"

namespace tsah {

class ParallelReinsertionOptimizer {
 public:
  // Shared with the sequential optimizer: cost, k, seed, stop rule (batches are rounds here), time
  // limit, round limit, progress (called after every round). Node selection and batch sizes are
  // the sequential optimizer's and do not apply here.
  using Config = InsertionOptimizer::Config;
  using Result = InsertionOptimizer::Result;

  struct Parallel {
    unsigned threads = 0;            // worker threads; 0: all cores
    // Share of the eligible nodes searched per round: smaller rounds converge with fewer wasted
    // searches, larger ones to a slightly lower cost (100k triangles: 0.1 -> +1.2%, 0.5 -> +0.8%
    // over the sequential optimizer's cost).
    double candidateFraction = 0.25;
  };

  ParallelReinsertionOptimizer() = default;
  explicit ParallelReinsertionOptimizer(Config config);  // default Parallel settings
  ParallelReinsertionOptimizer(Config config, Parallel parallel);
  const Config& config() const { return config_; }

  // Optimizes a valid tree over prims (any leaf sizes). Result::steps counts searches,
  // Result::acceptedSteps applied moves, Result::history one record per round. With `collapse`,
  // Result::bvh is the optimized tree collapsed by it: the same tree as collapse->collapse() of the
  // tree returned without it, made without a second copy of every node's boxes (memory).
  Result optimize(Bvh bvh, const PrimitiveBoxes& prims, const LeafCollapser* collapse = nullptr) const;

 private:
  Config config_;
  Parallel parallel_;
};

struct ReinsertionRoundStats {
  uint64_t candidates = 0;  // nodes searched
  uint64_t improving = 0;   // searches that found a better position
  uint64_t winners = 0;     // moves left after conflict resolution
  uint64_t applied = 0;     // moves kept and applied
};

// One tree under parallel reinsertion, round by round: the CPU session below, the GPU session
// (tsah_cuda/gpu_optimizer.hpp) and its host emulation (tsah/reinsertion_emulation.hpp).
class RoundSession {
 public:
  using RoundStats = ReinsertionRoundStats;
  virtual ~RoundSession() = default;
  // One round. Focused (the optimizer's default): a node whose last search found nothing is
  // searched again only after a move touched it or one of its 4 nearest ancestors; a full round
  // searches every sampled node.
  virtual RoundStats round(bool focused = true) = 0;
  // After a round: new weights for k > 0 from costs recomputed from the boxes (k = 0: nothing).
  virtual void endRound() = 0;
  virtual double cost() const = 0;                  // C~^k of the tracked frame costs
  virtual std::vector<double> frameCostList() const = 0;  // C_i, updated by every applied move
  virtual Bvh bvh() const = 0;                      // the current tree with boxes for every frame
  virtual Bvh topology() const = 0;                 // the same without boxes (frameCount 0)
  // The tree (collapsed by `collapse` when given); the session is unusable afterwards.
  virtual Bvh releaseTree(const LeafCollapser* collapse) = 0;
  virtual uint64_t searches() const = 0;
  virtual uint64_t appliedMoves() const = 0;
};

// The optimizer's loop over any session: rounds until the stop rule (see the header comment),
// history, progress, limits. `seconds` counts from `start` (the session's setup included).
InsertionOptimizer::Result runReinsertionRounds(RoundSession& session, const InsertionOptimizer::Config& config,
                                                const LeafCollapser* collapse,
                                                std::chrono::steady_clock::time_point start);

// The round-level machinery behind ParallelReinsertionOptimizer, public so that tests can check the
// tree after every round.
class ReinsertionSession final : public RoundSession {
 public:
  // Throws tsah::DataError when prims does not match the tree. prims must outlive the session.
  ReinsertionSession(Bvh bvh, const PrimitiveBoxes& prims, const ParallelReinsertionOptimizer::Config& config,
                     const ParallelReinsertionOptimizer::Parallel& parallel);
  ~ReinsertionSession() override;
  ReinsertionSession(ReinsertionSession&&) noexcept;
  ReinsertionSession& operator=(ReinsertionSession&&) noexcept;

  RoundStats round(bool focused = true) override;
  void endRound() override;

  double cost() const override;
  std::span<const double> frameCosts() const;  // C_i, updated by every applied move
  std::vector<double> frameCostList() const override;
  Bvh bvh() const override;
  Bvh topology() const override;
  Bvh release();                               // the tree; the session is unusable afterwards
  // collapser.collapse(release()), with the peak memory of the session alone (see the .cpp).
  Bvh releaseCollapsed(const LeafCollapser& collapser);
  Bvh releaseTree(const LeafCollapser* collapse) override;
  uint64_t searches() const override;
  uint64_t appliedMoves() const override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tsah
