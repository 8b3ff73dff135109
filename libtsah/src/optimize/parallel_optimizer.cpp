// The optimizer's driver: rounds of ReinsertionSession (reinsertion_session.cpp) until the stop rule.
#include <algorithm>
#include <chrono>
#include <string>
#include <utility>

#include "optimize/optimizer_run.hpp"
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
  std::vector<double> frameCosts;  // RoundSession gives them by value: kept alive for the RunState
  const auto state = [&session, &frameCosts] {
    frameCosts = session.frameCostList();
    return RunState{session.cost(), frameCosts, session.searches(), session.appliedMoves()};
  };
  OptimizerRun run(config, start, state());
  bool focused = true;
  for (uint32_t round = 1;; ++round) {
    const RoundSession::RoundStats stats = session.round(focused);
    session.endRound();
    // Debug builds: the round's moves left a tree over every primitive (topology() gathers it, from
    // the device for the GPU session; release builds skip both).
    TSAH_ASSERT_VALID(validate(session.topology()),
                      "parallel reinsertion: the tree after round " + std::to_string(round));
    // Stalled focused rounds get one full round before the run ends: nodes skipped as quiet may
    // have found new places after changes elsewhere.
    const bool stalled = run.endBatch(round, state()) || stats.candidates == 0;
    if (stalled && !focused) break;
    focused = !stalled;
    if (run.limitReached(round)) break;
  }
  run.finalState(state());
  return run.finish(session.releaseTree(collapse));
}

}  // namespace tsah
