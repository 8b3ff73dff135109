#pragma once
// What the sequential insertion optimizer (batches of steps) and parallel reinsertion (rounds, on
// the CPU, the GPU or its emulation) share when they run: the clock, the history of batches with
// the progress callback, the stop rule and the result. Each optimizer keeps only its own loop.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <memory>
#include <span>

#include "tsah/core/cost.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/optimize/leaf_collapser.hpp"

namespace tsah {

// The stop rule: a batch improves when it lowers the best cost so far by at least the fraction
// minImprovement; the run stalls after `patience` batches in a row that do not.
class StallCounter {
 public:
  StallCounter(double initialCost, double minImprovement, uint32_t patience)
      : best_(initialCost), minImprovement_(minImprovement), patience_(patience) {}

  // Records the cost after a batch; true once `patience` batches in a row did not improve.
  bool stalledAfter(double cost) {
    without_ = cost < best_ * (1.0 - minImprovement_) ? 0 : without_ + 1;
    best_ = std::min(best_, cost);
    return without_ >= patience_;
  }

 private:
  double best_;
  double minImprovement_;
  uint32_t patience_;
  uint32_t without_ = 0;
};

// An optimizer session's tree collapsed from its node records, which are freed (with the rest of
// the session) before the collapsed tree's boxes are computed from the primitives: every node's
// boxes are never held twice.
template <class SessionImpl>
Bvh releaseCollapsedTree(std::unique_ptr<SessionImpl>& session, const LeafCollapser& collapser) {
  const PrimitiveBoxes& prims = *session->prims;
  Bvh out = collapser.collapseTopology(session->collapseSource());
  session.reset();
  refit(out, prims);
  return out;
}

// An optimizer's state as the run records it.
struct RunState {
  double cost = 0.0;                  // C~^k
  std::span<const double> frameCosts; // C_i
  uint64_t steps = 0, acceptedSteps = 0;
};

class OptimizerRun {
 public:
  using Clock = std::chrono::steady_clock;

  // Records batch 0 (the starting tree).
  OptimizerRun(const InsertionOptimizer::Config& config, Clock::time_point start, const RunState& initial)
      : config_(config), start_(start), stall_(initial.cost, config.minImprovement, config.batchesWithoutImprovement) {
    result_.initialFrameCosts.assign(initial.frameCosts.begin(), initial.frameCosts.end());
    result_.initialCost = initial.cost;
    record(0, initial);
  }

  double elapsed() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }
  bool timeLimited() const { return config_.timeLimitSeconds > 0.0; }
  bool pastTimeLimit() const { return timeLimited() && elapsed() >= config_.timeLimitSeconds; }

  // Throws tsah::Cancelled once the caller's cancel check says so.
  void throwIfCancelled() const { tsah::throwIfCancelled(config_); }

  // Records a finished batch; true when it stalled the run (the stop rule). Throws tsah::Cancelled
  // when the caller cancelled the run.
  bool endBatch(uint32_t batch, const RunState& state) {
    throwIfCancelled();
    record(batch, state);
    return stall_.stalledAfter(state.cost);
  }

  // True when the batch limit or the time limit ends the run after `batch`.
  bool limitReached(uint32_t batch) {
    if (config_.maxBatches && batch >= config_.maxBatches) return true;
    if (pastTimeLimit()) result_.timeLimitReached = true;
    return result_.timeLimitReached;
  }

  // The final state, copied before the optimizer gives up its tree (and the state with it).
  void finalState(const RunState& state) {
    result_.finalFrameCosts.assign(state.frameCosts.begin(), state.frameCosts.end());
    result_.finalCost = state.cost;
    result_.steps = state.steps;
    result_.acceptedSteps = state.acceptedSteps;
    result_.seconds = elapsed();
  }

  // The result with the optimizer's tree (collapsed when asked), its depth bounded by limitDepth.
  InsertionOptimizer::Result finish(Bvh tree) {
    limitDepth(tree);
    result_.bvh = std::move(tree);
    return std::move(result_);
  }

 private:
  void record(uint32_t batch, const RunState& state) {
    InsertionOptimizer::BatchRecord r;
    r.batch = batch;
    r.cost = state.cost;
    r.averageCost = temporalCost(state.frameCosts, 0);
    r.elapsedSeconds = elapsed();
    r.steps = state.steps;
    r.acceptedSteps = state.acceptedSteps;
    result_.history.push_back(r);
    if (config_.progress) config_.progress(r);
  }

  const InsertionOptimizer::Config& config_;
  Clock::time_point start_;
  StallCounter stall_;
  InsertionOptimizer::Result result_;
};

}  // namespace tsah
