// The optimizer's driver: rounds of ReinsertionSession (reinsertion_session.cpp) until the stop rule.
#include <algorithm>
#include <chrono>
#include <string>
#include <utility>

#include "optimize/stop_rule.hpp"
#include "tsah/base/assert.hpp"
#include "tsah/base/error.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"

namespace tsah {

ParallelReinsertionOptimizer::ParallelReinsertionOptimizer(Config config)
    : ParallelReinsertionOptimizer(std::move(config), Parallel{}) {}

ParallelReinsertionOptimizer::ParallelReinsertionOptimizer(Config config, Parallel parallel)
    : config_(std::move(config)), parallel_(parallel) {
  if (config_.k < 0) throw tsah::ConfigError("ParallelReinsertionOptimizer: the exponent k must be >= 0");
  if (config_.batchesWithoutImprovement == 0)
    throw tsah::ConfigError("ParallelReinsertionOptimizer: batchesWithoutImprovement must be >= 1");
  if (!(parallel_.candidateFraction > 0.0) || parallel_.candidateFraction > 1.0)
    throw tsah::ConfigError("ParallelReinsertionOptimizer: candidateFraction must be in (0, 1]");
}

ParallelReinsertionOptimizer::Result ParallelReinsertionOptimizer::optimize(Bvh bvh, const PrimitiveBoxes& prims,
                                                                           const LeafCollapser* collapse) const {
  const auto start = std::chrono::steady_clock::now();
  ReinsertionSession session(std::move(bvh), prims, config_, parallel_);
  return runReinsertionRounds(session, config_, collapse, start);
}

InsertionOptimizer::Result runReinsertionRounds(RoundSession& session, const InsertionOptimizer::Config& config,
                                                const LeafCollapser* collapse,
                                                std::chrono::steady_clock::time_point start) {
  using Clock = std::chrono::steady_clock;
  const auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  InsertionOptimizer::Result result;
  result.initialFrameCosts = session.frameCostList();
  result.initialCost = session.cost();
  const auto record = [&](uint32_t round) {
    InsertionOptimizer::BatchRecord r;
    r.batch = round;
    r.cost = session.cost();
    r.averageCost = temporalCost(session.frameCostList(), 0);
    r.elapsedSeconds = elapsed();
    r.steps = session.searches();
    r.acceptedSteps = session.appliedMoves();
    result.history.push_back(r);
    if (config.progress) config.progress(r);
  };
  record(0);
  StallCounter stall(session.cost(), config.minImprovement, config.batchesWithoutImprovement);
  bool focused = true;
  for (uint32_t round = 1;; ++round) {
    const RoundSession::RoundStats stats = session.round(focused);
    session.endRound();
    // Debug builds: the round's moves left a tree over every primitive (topology() gathers it, from
    // the device for the GPU session; release builds skip both).
    TSAH_ASSERT_VALID(validate(session.topology()),
                      "parallel reinsertion: the tree after round " + std::to_string(round));
    record(round);
    // Stalled focused rounds get one full round before the run ends: nodes skipped as quiet may
    // have found new places after changes elsewhere.
    const bool stalled = stall.stalledAfter(session.cost()) || stats.candidates == 0;
    if (stalled && !focused) break;
    focused = !stalled;
    if (config.maxBatches && round >= config.maxBatches) break;
    if (config.timeLimitSeconds > 0.0 && elapsed() >= config.timeLimitSeconds) {
      result.timeLimitReached = true;
      break;
    }
  }
  result.finalFrameCosts = session.frameCostList();
  result.finalCost = session.cost();
  result.steps = session.searches();
  result.acceptedSteps = session.appliedMoves();
  result.seconds = elapsed();
  result.bvh = session.releaseTree(collapse);
  return result;
}

}  // namespace tsah
