// InsertionOptimizer and its step-level session: tree invariants and exact cost tracking after
// every step, undo, convergence properties, determinism, the temporal grouping T-SAH must find.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/build/sah_builder.hpp"
#include "test_support.hpp"

namespace {

using tsah::Bvh;
using tsah::InsertionOptimizer;
using tsah::InsertionSession;
using Selection = InsertionOptimizer::Selection;

// Random triangles moving with random velocities: the frame-0 grouping degrades over time.
using tsah::test::movingTriangleBoxes;

Bvh initialTree(const tsah::PrimitiveBoxes& prims) {
  Bvh bvh = tsah::SweepSahBuilder().build(prims.frame(0));
  tsah::refit(bvh, prims);
  return bvh;
}

double bruteForceCost(const Bvh& bvh, int k) { return tsah::temporalCost(tsah::frameCosts(bvh), k); }

bool sameTree(const Bvh& a, const Bvh& b) {
  if (!tsah::test::sameTopology(a, b) || a.boxes.size() != b.boxes.size()) return false;
  for (std::size_t i = 0; i < a.boxes.size(); ++i)
    if (a.boxes[i].lo.x != b.boxes[i].lo.x || a.boxes[i].hi.y != b.boxes[i].hi.y ||
        a.boxes[i].hi.z != b.boxes[i].hi.z || a.boxes[i].lo.z != b.boxes[i].lo.z)
      return false;
  return true;
}

// Pairs of triangles that swap partners: in each of 8 clusters (corners of a cube), A-B and C-D
// are neighbours in frame 0, A-C and B-D in frames 1..4. A tree for frame 0 pairs them wrongly for
// most of the animation.
tsah::PrimitiveBoxes swappingPairs(uint32_t frames) {
  const float y0[4] = {0, 0, 8, 8}, x0[4] = {0, 1, 0, 1};  // A B C D in frame 0
  const float y1[4] = {0, 8, 0, 8}, x1[4] = {0, 0, 1, 1};  // A B C D later: A-C, B-D
  std::vector<uint32_t> indices;
  std::vector<float> positions;
  const uint32_t clusters = 8, triangles = clusters * 4;
  for (uint32_t i = 0; i < triangles * 3; ++i) indices.push_back(i);
  for (uint32_t f = 0; f < frames; ++f)
    for (uint32_t c = 0; c < clusters; ++c)
      for (int t = 0; t < 4; ++t) {
        const float x = float(c & 1) * 30.0f + (f == 0 ? x0[t] : x1[t]);
        const float y = float((c >> 1) & 1) * 30.0f + (f == 0 ? y0[t] : y1[t]);
        const float z = float(c >> 2) * 30.0f;
        const float corners[3][3] = {{x, y, z}, {x + 0.3f, y, z}, {x, y + 0.3f, z + 0.3f}};
        for (const auto& p : corners) positions.insert(positions.end(), p, p + 3);
      }
  return tsah::triangleBoxes(indices, positions, frames);
}

uint32_t parentOfPrim(const Bvh& bvh, uint32_t prim) {
  for (uint32_t n = 0; n < bvh.nodeCount(); ++n) {
    const tsah::BvhNode& node = bvh.nodes[n];
    if (node.isLeaf() && bvh.primIds[node.primBegin] == prim) return node.parent;
  }
  return tsah::kInvalidIndex;
}

TEST(InsertionSession, InvariantsAndExactCostAfterEveryStep) {
  tsah::test::forEachSeedFramesAndK({1u, 3u}, 40, 30, [](const tsah::PrimitiveBoxes& prims, uint32_t seed, int k) {
    InsertionOptimizer::Config config;
    config.k = k;
    config.seed = seed;
    config.selection = seed == 2 ? Selection::Uniform : Selection::MetropolisHastings;
    InsertionSession session(initialTree(prims), prims, config);
    double previous = session.cost();
    EXPECT_NEAR(previous, bruteForceCost(session.bvh(), k), 1e-9 * previous);
    for (int step = 0; step < 300; ++step) {
      const uint32_t node = session.selectNode();
      ASSERT_TRUE(session.eligible(node));
      const Bvh before = session.bvh();
      const bool kept = session.step(node);
      const auto problem = tsah::validate(session.bvh(), &prims);
      ASSERT_FALSE(problem.has_value()) << "step " << step << ": " << *problem;
      const double expected = bruteForceCost(session.bvh(), k);
      ASSERT_NEAR(session.cost(), expected, 1e-9 * expected) << "step " << step;
      const std::vector<double> perFrame = tsah::frameCosts(session.bvh());
      for (uint32_t f = 0; f < prims.frameCount; ++f)
        ASSERT_NEAR(session.frameCosts()[f], perFrame[f], 1e-9 * perFrame[f]);
      if (kept) {
        EXPECT_LE(session.cost(), previous * (1 + 1e-12)) << "a kept step raised the cost";
      } else {
        EXPECT_TRUE(sameTree(before, session.bvh())) << "an undone step changed the tree";
      }
      previous = session.cost();
    }
    session.refresh();
    EXPECT_NEAR(session.cost(), previous, 1e-9 * previous);
  });
}

TEST(InsertionSession, StepsOnEveryNodeKeepTheTreeValid) {
  // Exhaustively step every eligible node of a small tree, several rounds.
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(24, 2, 7);
  InsertionSession session(initialTree(prims), prims, {});
  for (int round = 0; round < 3; ++round)
    for (uint32_t n = 0; n < session.bvh().nodeCount(); ++n) {
      if (!session.eligible(n)) continue;
      session.step(n);
      const auto problem = tsah::validate(session.bvh(), &prims);
      ASSERT_FALSE(problem.has_value()) << *problem;
    }
  EXPECT_THROW(session.step(session.bvh().root), tsah::ConfigError);
}

TEST(InsertionSession, MetropolisHastingsNeverRepeatsTheLastNode) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(200, 2, 5);
  InsertionSession session(initialTree(prims), prims, {});
  uint32_t last = tsah::kInvalidIndex;
  for (int i = 0; i < 200; ++i) {
    const uint32_t node = session.selectNode();
    ASSERT_TRUE(session.eligible(node));
    EXPECT_NE(node, last);
    last = node;
  }
}

TEST(InsertionSession, BatchSortTakesTheMostInefficientNodes) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(150, 3, 8);
  InsertionSession session(initialTree(prims), prims, {});
  const std::vector<uint32_t> batch = session.batchSortNodes(20);
  ASSERT_EQ(batch.size(), 20u);
  for (uint32_t n : batch) EXPECT_TRUE(session.eligible(n));
  std::vector<uint32_t> unique = batch;
  std::sort(unique.begin(), unique.end());
  EXPECT_EQ(std::unique(unique.begin(), unique.end()), unique.end());
  // Asking for more nodes than are eligible gives every eligible node.
  uint32_t eligible = 0;
  for (uint32_t n = 0; n < session.bvh().nodeCount(); ++n) eligible += session.eligible(n);
  EXPECT_EQ(session.batchSortNodes(100000).size(), eligible);
}

TEST(InsertionOptimizer, NeverEndsAboveItsStartAndHistoryIsMonotone) {
  for (Selection selection : {Selection::MetropolisHastings, Selection::Uniform, Selection::BatchSort}) {
    for (int k : {0, 2, 4}) {
      const tsah::PrimitiveBoxes prims = movingTriangleBoxes(300, 4, 11 + uint32_t(k));
      InsertionOptimizer::Config config;
      config.k = k;
      config.selection = selection;
      uint32_t callbacks = 0;
      config.progress = [&](const InsertionOptimizer::BatchRecord&) { ++callbacks; };
      const Bvh start = initialTree(prims);
      const double startCost = bruteForceCost(start, k);
      const InsertionOptimizer::Result result = InsertionOptimizer(config).optimize(start, prims);
      ASSERT_FALSE(tsah::validate(result.bvh, &prims).has_value());
      EXPECT_NEAR(result.initialCost, startCost, 1e-9 * startCost);
      EXPECT_LE(result.finalCost, result.initialCost);
      EXPECT_NEAR(result.finalCost, bruteForceCost(result.bvh, k), 1e-9 * result.finalCost);
      ASSERT_GE(result.history.size(), 4u);  // the start plus at least 3 batches
      EXPECT_EQ(callbacks, result.history.size());
      for (std::size_t i = 0; i < result.history.size(); ++i) {
        EXPECT_EQ(result.history[i].batch, i);
        if (i) {
          EXPECT_LE(result.history[i].cost, result.history[i - 1].cost * (1 + 1e-12));
        }
      }
      EXPECT_EQ(result.history.back().cost, result.finalCost);
      if (selection != Selection::BatchSort) {  // moving triangles leave plenty to improve
        EXPECT_LT(result.finalCost, 0.97 * result.initialCost);
      }
    }
  }
}

TEST(InsertionOptimizer, KZeroOptimizesTheMeanFrameCost) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(250, 5, 21);
  const InsertionOptimizer::Result result = InsertionOptimizer().optimize(initialTree(prims), prims);
  const std::vector<double> perFrame = tsah::frameCosts(result.bvh);
  double mean = 0;
  for (double c : perFrame) mean += c / double(perFrame.size());
  EXPECT_NEAR(result.finalCost, mean, 1e-9 * mean);
  for (std::size_t f = 0; f < perFrame.size(); ++f)
    EXPECT_NEAR(result.finalFrameCosts[f], perFrame[f], 1e-9 * perFrame[f]);
  EXPECT_NEAR(result.history.back().averageCost, mean, 1e-9 * mean);
}

TEST(InsertionOptimizer, OneFrameTsahEqualsSahOptimization) {
  // With one frame every weight is 1: T-SAH of any k is SAH optimization, step for step.
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(400, 1, 31);
  InsertionOptimizer::Config sah;
  sah.seed = 5;
  InsertionOptimizer::Config tsah4 = sah;
  tsah4.k = 4;
  const auto a = InsertionOptimizer(sah).optimize(initialTree(prims), prims);
  const auto b = InsertionOptimizer(tsah4).optimize(initialTree(prims), prims);
  EXPECT_TRUE(sameTree(a.bvh, b.bvh));
  EXPECT_DOUBLE_EQ(a.finalCost, b.finalCost);
  EXPECT_DOUBLE_EQ(a.finalCost, tsah::frameCost(a.bvh, 0));
  EXPECT_LT(a.finalCost, a.initialCost);
}

TEST(InsertionOptimizer, TsahFindsTheTemporalGroupingSah0DoesNot) {
  const uint32_t clusters = 8;
  const tsah::PrimitiveBoxes prims = swappingPairs(5);
  const Bvh sah0 = initialTree(prims);
  const std::vector<double> sah0Costs = tsah::frameCosts(sah0);
  for (uint32_t c = 0; c < clusters; ++c) {  // SAH0 pairs the frame-0 neighbours
    EXPECT_EQ(parentOfPrim(sah0, 4 * c), parentOfPrim(sah0, 4 * c + 1));
    EXPECT_EQ(parentOfPrim(sah0, 4 * c + 2), parentOfPrim(sah0, 4 * c + 3));
  }
  for (Selection selection : {Selection::MetropolisHastings, Selection::Uniform}) {
    for (uint64_t seed : {1u, 2u, 3u}) {
      InsertionOptimizer::Config config;
      config.selection = selection;
      config.seed = seed;
      const auto result = InsertionOptimizer(config).optimize(sah0, prims);
      ASSERT_FALSE(tsah::validate(result.bvh, &prims).has_value());
      for (uint32_t c = 0; c < clusters; ++c) {  // T-SAH pairs the partners of most frames
        const uint32_t a = 4 * c, b = a + 1, cc = a + 2, d = a + 3;
        EXPECT_EQ(parentOfPrim(result.bvh, a), parentOfPrim(result.bvh, cc)) << "cluster " << c << " seed " << seed;
        EXPECT_EQ(parentOfPrim(result.bvh, b), parentOfPrim(result.bvh, d)) << "cluster " << c << " seed " << seed;
      }
      EXPECT_LT(result.finalCost, tsah::temporalCost(sah0Costs, 0));
      for (uint32_t f = 1; f < 5; ++f) EXPECT_LT(result.finalFrameCosts[f], sah0Costs[f]);
    }
  }
}

TEST(InsertionOptimizer, SameSeedSameTree) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(500, 3, 41);
  for (Selection selection : {Selection::MetropolisHastings, Selection::Uniform, Selection::BatchSort}) {
    InsertionOptimizer::Config config;
    config.seed = 99;
    config.k = 2;
    config.selection = selection;
    const auto a = InsertionOptimizer(config).optimize(initialTree(prims), prims);
    const auto b = InsertionOptimizer(config).optimize(initialTree(prims), prims);
    EXPECT_TRUE(sameTree(a.bvh, b.bvh));
    EXPECT_EQ(a.steps, b.steps);
    EXPECT_EQ(a.finalCost, b.finalCost);
  }
}

TEST(InsertionOptimizer, TimeLimitAndBatchLimitStopEarly) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(2000, 2, 51);
  InsertionOptimizer::Config config;
  config.timeLimitSeconds = 1e-9;
  const auto limited = InsertionOptimizer(config).optimize(initialTree(prims), prims);
  EXPECT_TRUE(limited.timeLimitReached);
  EXPECT_EQ(limited.history.size(), 2u);
  EXPECT_LE(limited.steps, 32u);
  EXPECT_FALSE(tsah::validate(limited.bvh, &prims).has_value());

  InsertionOptimizer::Config batches;
  batches.maxBatches = 2;
  const auto two = InsertionOptimizer(batches).optimize(initialTree(prims), prims);
  EXPECT_EQ(two.history.size(), 3u);
  EXPECT_FALSE(two.timeLimitReached);
}

TEST(InsertionOptimizer, TinyTreesAndBadInput) {
  // Three primitives: no node is eligible; the tree comes back unchanged.
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(3, 2, 61);
  const Bvh start = initialTree(prims);
  const auto result = InsertionOptimizer().optimize(start, prims);
  EXPECT_TRUE(sameTree(start, result.bvh));
  EXPECT_EQ(result.steps, 0u);

  const tsah::PrimitiveBoxes other = movingTriangleBoxes(5, 2, 62);
  EXPECT_THROW(InsertionOptimizer().optimize(start, other), tsah::DataError);
  InsertionOptimizer::Config negative;
  negative.k = -1;
  EXPECT_THROW(InsertionOptimizer{negative}, tsah::ConfigError);
  InsertionOptimizer::Config fraction;
  fraction.batchFraction = 0.0;
  EXPECT_THROW(InsertionOptimizer{fraction}, tsah::ConfigError);
}

}  // namespace
