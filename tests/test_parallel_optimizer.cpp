// ParallelReinsertionOptimizer and its round-level session: tree invariants and exact cost tracking
// after every round, never above the start, determinism over seeds and thread counts, quality
// against the sequential optimizer, the temporal grouping T-SAH must find, bad input.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <vector>

#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"
#include "tsah/build/sah_builder.hpp"

namespace {

using tsah::Bvh;
using tsah::ParallelReinsertionOptimizer;
using tsah::ReinsertionSession;

using tsah::test::frameZeroSahTree;
using tsah::test::movingTriangleBoxes;

ParallelReinsertionOptimizer::Parallel settings(unsigned threads, double fraction = 0.5) {
  ParallelReinsertionOptimizer::Parallel p;
  p.threads = threads;
  p.candidateFraction = fraction;
  return p;
}

using tsah::test::identicalTree;

bool sameTree(const Bvh& a, const Bvh& b) { return tsah::test::sameTopology(a, b) && a.boxes.size() == b.boxes.size(); }

TEST(ReinsertionSession, InvariantsAndExactCostAfterEveryRound) {
  tsah::test::expectRoundsValidAndImproving(
      [](Bvh tree, const tsah::PrimitiveBoxes& prims, const ParallelReinsertionOptimizer::Config& config, double f) {
        return std::make_unique<ReinsertionSession>(std::move(tree), prims, config, settings(2, f));
      });
}

// Moves the subtree l next to x (as the search's moves do, reusing l's parent), then refits.
Bvh movedTree(Bvh bvh, uint32_t l, uint32_t x, const tsah::PrimitiveBoxes& prims) {
  auto& nodes = bvh.nodes;
  const auto replaceChild = [&](uint32_t parent, uint32_t from, uint32_t to) {
    (nodes[parent].left == from ? nodes[parent].left : nodes[parent].right) = to;
  };
  const uint32_t p = nodes[l].parent, g = nodes[p].parent;
  const uint32_t s = nodes[p].left == l ? nodes[p].right : nodes[p].left;
  replaceChild(g, p, s);
  nodes[s].parent = g;
  const uint32_t xp = nodes[x].parent;
  nodes[p].parent = xp;
  nodes[p].left = x;
  nodes[p].right = l;
  nodes[x].parent = p;
  nodes[l].parent = p;
  if (xp == tsah::kInvalidIndex) bvh.root = p;
  else replaceChild(xp, x, p);
  tsah::refit(bvh, prims);
  return bvh;
}

bool inSubtree(const Bvh& bvh, uint32_t node, uint32_t top) {
  for (uint32_t n = node; n != tsah::kInvalidIndex; n = bvh.nodes[n].parent)
    if (n == top) return true;
  return false;
}

// Once a round searching every node finds nothing, no single move (any L, any X, tried by brute
// force) lowers the cost: the branch-and-bound search misses no position.
TEST(ReinsertionSession, ConvergedTreeHasNoImprovingSingleMove) {
  for (uint32_t seed : {5u, 6u}) {
    const tsah::PrimitiveBoxes prims = movingTriangleBoxes(40, 3, seed);
    ReinsertionSession session(frameZeroSahTree(prims), prims, {}, settings(2, 1.0));
    int rounds = 0;
    while (session.round().improving > 0 && ++rounds < 500) {
    }
    ASSERT_LT(rounds, 500);
    const Bvh tree = session.bvh();
    const double cost = session.cost();
    for (uint32_t l = 0; l < tree.nodeCount(); ++l) {
      const uint32_t p = tree.nodes[l].parent;
      if (l == tree.root || p == tree.root) continue;
      for (uint32_t x = 0; x < tree.nodeCount(); ++x) {
        const uint32_t sibling = tree.nodes[p].left == l ? tree.nodes[p].right : tree.nodes[p].left;
        if (x == p || x == sibling || inSubtree(tree, x, l)) continue;
        const double moved = tsah::temporalCost(tsah::frameCosts(movedTree(tree, l, x, prims)), 0);
        EXPECT_GE(moved, cost * (1 - 1e-6)) << "moving " << l << " next to " << x;
      }
    }
  }
}

TEST(ParallelReinsertionOptimizer, NeverEndsAboveItsStartAndHistoryIsMonotone) {
  tsah::test::expectRunsNeverEndAboveTheStart(
      [](Bvh tree, const tsah::PrimitiveBoxes& prims, const ParallelReinsertionOptimizer::Config& config) {
        return ParallelReinsertionOptimizer(config, settings(2)).optimize(std::move(tree), prims);
      },
      [](const ParallelReinsertionOptimizer::Result& result) {
        EXPECT_EQ(result.history.back().acceptedSteps, result.acceptedSteps);
      });
}

TEST(ParallelReinsertionOptimizer, SameSeedSameTreeForAnyThreadCount) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(1500, 3, 41);
  ParallelReinsertionOptimizer::Config config;
  config.seed = 99;
  config.k = 2;
  const auto one = ParallelReinsertionOptimizer(config, settings(1)).optimize(frameZeroSahTree(prims), prims);
  const auto again = ParallelReinsertionOptimizer(config, settings(1)).optimize(frameZeroSahTree(prims), prims);
  const auto two = ParallelReinsertionOptimizer(config, settings(2)).optimize(frameZeroSahTree(prims), prims);
  const auto four = ParallelReinsertionOptimizer(config, settings(4)).optimize(frameZeroSahTree(prims), prims);
  for (const auto* other : {&again, &two, &four}) {
    EXPECT_TRUE(sameTree(one.bvh, other->bvh));
    EXPECT_EQ(one.finalCost, other->finalCost);
    EXPECT_EQ(one.acceptedSteps, other->acceptedSteps);
  }
  config.seed = 100;
  const auto otherSeed = ParallelReinsertionOptimizer(config, settings(2)).optimize(frameZeroSahTree(prims), prims);
  EXPECT_FALSE(sameTree(one.bvh, otherSeed.bvh));
}

TEST(ParallelReinsertionOptimizer, WithinThreePercentOfTheSequentialOptimizer) {
  for (uint32_t seed : {11u, 12u, 13u}) {
    for (int k : {0, 2}) {
      const tsah::PrimitiveBoxes prims = movingTriangleBoxes(2000, 5, seed);
      tsah::InsertionOptimizer::Config config;
      config.k = k;
      config.seed = seed;
      const auto sequential = tsah::InsertionOptimizer(config).optimize(frameZeroSahTree(prims), prims);
      const auto parallel = ParallelReinsertionOptimizer(config, settings(2)).optimize(frameZeroSahTree(prims), prims);
      std::printf("seed %u k %d: parallel / sequential = %.4f\n", seed, k, parallel.finalCost / sequential.finalCost);
      EXPECT_LT(parallel.finalCost, 1.03 * sequential.finalCost)
          << "seed " << seed << " k " << k << ": parallel " << parallel.finalCost << ", sequential "
          << sequential.finalCost;
    }
  }
}

// Both optimizers collapse from their own storage (memory): the result must be exactly the tree,
// boxes included, that collapsing their uncollapsed result gives.
TEST(ParallelReinsertionOptimizer, CollapseOnReleaseGivesExactlyTheCollapsedResult) {
  for (uint32_t frames : {1u, 4u}) {
    for (int k : {0, 2}) {
      for (uint32_t maxLeaf : {2u, 8u}) {
        const tsah::PrimitiveBoxes prims = movingTriangleBoxes(1200, frames, 70 + frames + k);
        const tsah::LeafCollapser collapser({k, {}, maxLeaf});
        ParallelReinsertionOptimizer::Config config;
        config.k = k;
        const ParallelReinsertionOptimizer parallel(config, settings(2));
        const auto plain = parallel.optimize(frameZeroSahTree(prims), prims);
        const auto direct = parallel.optimize(frameZeroSahTree(prims), prims, &collapser);
        const Bvh expected = collapser.collapse(plain.bvh);
        EXPECT_LT(expected.nodeCount(), plain.bvh.nodeCount());
        EXPECT_TRUE(identicalTree(expected, direct.bvh)) << "parallel, frames " << frames << " k " << k;
        EXPECT_EQ(plain.finalCost, direct.finalCost);

        const tsah::InsertionOptimizer sequential(config);
        const auto plainSequential = sequential.optimize(frameZeroSahTree(prims), prims);
        const auto directSequential = sequential.optimize(frameZeroSahTree(prims), prims, &collapser);
        EXPECT_TRUE(identicalTree(collapser.collapse(plainSequential.bvh), directSequential.bvh))
            << "sequential, frames " << frames << " k " << k;
      }
    }
  }
}

TEST(ParallelReinsertionOptimizer, LimitsTinyTreesAndBadInput) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(2000, 2, 51);
  ParallelReinsertionOptimizer::Config rounds;
  rounds.maxBatches = 2;
  const auto two = ParallelReinsertionOptimizer(rounds).optimize(frameZeroSahTree(prims), prims);
  EXPECT_EQ(two.history.size(), 3u);
  ParallelReinsertionOptimizer::Config limited;
  limited.timeLimitSeconds = 1e-9;
  const auto once = ParallelReinsertionOptimizer(limited).optimize(frameZeroSahTree(prims), prims);
  EXPECT_TRUE(once.timeLimitReached);
  EXPECT_EQ(once.history.size(), 2u);

  for (uint32_t count : {1u, 2u, 3u}) {  // no eligible node: the tree comes back unchanged
    const tsah::PrimitiveBoxes few = movingTriangleBoxes(count, 2, 60 + count);
    const auto result = ParallelReinsertionOptimizer().optimize(frameZeroSahTree(few), few);
    EXPECT_FALSE(tsah::validate(result.bvh, &few).has_value());
    EXPECT_EQ(result.acceptedSteps, 0u);
  }

  const tsah::PrimitiveBoxes other = movingTriangleBoxes(5, 2, 62);
  EXPECT_THROW(ParallelReinsertionOptimizer().optimize(frameZeroSahTree(prims), other), tsah::DataError);
  ParallelReinsertionOptimizer::Config negative;
  negative.k = -1;
  EXPECT_THROW(ParallelReinsertionOptimizer{negative}, tsah::ConfigError);
  EXPECT_THROW(ParallelReinsertionOptimizer({}, settings(1, 0.0)), tsah::ConfigError);
  EXPECT_THROW(ParallelReinsertionOptimizer({}, settings(1, 1.5)), tsah::ConfigError);
}

}  // namespace
