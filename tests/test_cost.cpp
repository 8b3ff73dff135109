// Cost model: Eq. 1 against a brute-force traversal, Eq. 3 against its definition, the evaluator of
// arbitrary frames against refit + Eq. 1.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/build/sah_builder.hpp"
#include "test_support.hpp"

namespace {

using tsah::Aabb;
using tsah::Bvh;

using Scene = tsah::test::MovingTriangles;

Scene randomScene(uint32_t triangles, uint32_t frames, uint32_t seed) {
  return tsah::test::randomMovingTriangles(triangles, frames, seed, 3.0f);
}

// Eq. 1 by recursion from the root (independent of the node array order).
void sumAreas(const Bvh& bvh, uint32_t n, uint32_t frame, double& inner, double& leaves) {
  const tsah::BvhNode& node = bvh.nodes[n];
  const double area = bvh.box(n, frame).area();
  if (node.isLeaf()) {
    leaves += area * node.primCount;
    return;
  }
  inner += area;
  sumAreas(bvh, node.left, frame, inner, leaves);
  sumAreas(bvh, node.right, frame, inner, leaves);
}

double bruteForceCost(const Bvh& bvh, uint32_t frame, double ct, double ci) {
  double inner = 0, leaves = 0;
  sumAreas(bvh, bvh.root, frame, inner, leaves);
  return (ct * inner + ci * leaves) / bvh.box(bvh.root, frame).area();
}

TEST(Cost, FrameCostMatchesBruteForce) {
  const Scene s = randomScene(300, 4, 1);
  const tsah::PrimitiveBoxes prims = tsah::triangleBoxes(s.indices, s.positions, s.frames);
  Bvh bvh = tsah::SweepSahBuilder().build(prims.frame(0));
  tsah::refit(bvh, prims);
  for (const tsah::CostModel model : {tsah::CostModel{}, tsah::CostModel{1.0f, 1.0f}, tsah::CostModel{1.2f, 7.0f}}) {
    const std::vector<double> costs = tsah::frameCosts(bvh, model);
    ASSERT_EQ(costs.size(), 4u);
    for (uint32_t f = 0; f < 4; ++f) {
      EXPECT_NEAR(costs[f], bruteForceCost(bvh, f, model.ct, model.ci), 1e-9 * costs[f]);
      EXPECT_EQ(costs[f], tsah::frameCost(bvh, f, model));
    }
  }
  // The moving triangles spread apart: the frame-0 tree gets worse in later frames.
  const std::vector<double> costs = tsah::frameCosts(bvh);
  EXPECT_GT(costs[3], costs[0]);
}

TEST(Cost, SingleLeafAndSmallTrees) {
  Bvh leaf;
  leaf.nodes.push_back({tsah::kInvalidIndex, tsah::kInvalidIndex, tsah::kInvalidIndex, 0, 3});
  leaf.primIds = {0, 1, 2};
  leaf.boxes = {Aabb{{0, 0, 0}, {1, 1, 1}}};
  EXPECT_DOUBLE_EQ(tsah::frameCost(leaf, 0), 2.0 * 3);  // cI * j: every ray hits the root

  // Root with two unit-cube leaves inside a 2x1x1 box: (3 * 10 + 2 * (6 + 6)) / 10.
  const std::vector<Aabb> boxes = {Aabb{{0, 0, 0}, {1, 1, 1}}, Aabb{{1, 0, 0}, {2, 1, 1}}};
  const Bvh two = tsah::SweepSahBuilder().build(boxes);
  EXPECT_NEAR(tsah::frameCost(two, 0), (3.0 * 10 + 2.0 * 12) / 10.0, 1e-12);
  EXPECT_THROW(tsah::frameCost(two, 1), tsah::ConfigError);
}

TEST(Cost, DegenerateFrameCostIsEveryNode) {
  // All triangles collapsed onto one point: the root has no area.
  const std::vector<Aabb> boxes(5, Aabb{{1, 1, 1}, {1, 1, 1}});
  const Bvh bvh = tsah::SweepSahBuilder().build(boxes);
  EXPECT_DOUBLE_EQ(tsah::frameCost(bvh, 0), 3.0 * 4 + 2.0 * 5);
}

TEST(Cost, TemporalCostDefinition) {
  const std::vector<double> c = {10.0, 20.0, 40.0, 5.0};
  // k = 0: the plain average (Eq. 4).
  EXPECT_NEAR(tsah::temporalCost(c, 0), (10 + 20 + 40 + 5) / 4.0, 1e-12);
  // Eq. 3 by its definition.
  for (int k : {1, 2, 4}) {
    double num = 0, den = 0;
    for (double x : c) {
      num += std::pow(x, k + 1);
      den += std::pow(x, k);
    }
    EXPECT_NEAR(tsah::temporalCost(c, k), num / den, 1e-9 * num / den) << "k=" << k;
  }
  // Growing k moves the cost towards the maximum, never beyond it.
  EXPECT_LT(tsah::temporalCost(c, 0), tsah::temporalCost(c, 2));
  EXPECT_LT(tsah::temporalCost(c, 2), tsah::temporalCost(c, 4));
  EXPECT_LE(tsah::temporalCost(c, 400), 40.0);
  EXPECT_GT(tsah::temporalCost(c, 400), 39.9);
  // Large costs with large k do not overflow.
  const std::vector<double> big = {1e200, 2e200};
  EXPECT_TRUE(std::isfinite(tsah::temporalCost(big, 8)));
  EXPECT_EQ(tsah::temporalCost(std::vector<double>{}, 2), 0.0);
  EXPECT_THROW(tsah::temporalCost(c, -1), tsah::ConfigError);
}

TEST(Cost, TemporalWeightsAreNormalizedPowers) {
  const std::vector<double> c = {10.0, 20.0, 40.0};
  const std::vector<double> w0 = tsah::temporalWeights(c, 0);
  for (double w : w0) EXPECT_NEAR(w, 1.0 / 3.0, 1e-15);
  const std::vector<double> w2 = tsah::temporalWeights(c, 2);
  const double total = 100.0 + 400.0 + 1600.0;
  EXPECT_NEAR(w2[0], 100.0 / total, 1e-15);
  EXPECT_NEAR(w2[2], 1600.0 / total, 1e-15);
  // sum_i w_i C_i / sum_i w_i is the T-SAH cost (Eq. 2 = Eq. 3).
  EXPECT_NEAR(w2[0] * 10 + w2[1] * 20 + w2[2] * 40, tsah::temporalCost(c, 2), 1e-12);
}

TEST(Cost, TemporalCostOfATreeEqualsPerFrameRecomputation) {
  const Scene s = randomScene(200, 5, 2);
  const tsah::PrimitiveBoxes prims = tsah::triangleBoxes(s.indices, s.positions, s.frames);
  Bvh bvh = tsah::SweepSahBuilder().build(prims.frame(0));
  tsah::refit(bvh, prims);
  // Brute force: one single-frame copy of the tree per frame.
  std::vector<double> separate;
  for (uint32_t f = 0; f < s.frames; ++f) {
    tsah::PrimitiveBoxes one;
    one.frameCount = 1;
    one.primCount = prims.primCount;
    one.boxes.assign(prims.frame(f).begin(), prims.frame(f).end());
    Bvh copy = bvh;
    tsah::refit(copy, one);
    separate.push_back(bruteForceCost(copy, 0, 3.0, 2.0));
  }
  for (int k : {0, 2, 4}) {
    double num = 0, den = 0;
    for (double x : separate) {
      num += std::pow(x, k + 1);
      den += std::pow(x, k);
    }
    EXPECT_NEAR(tsah::temporalCost(tsah::frameCosts(bvh), k), num / den, 1e-9 * num / den);
  }
}

TEST(Cost, EvaluatorMatchesRefitOnAnyFrame) {
  const Scene s = randomScene(250, 3, 3);
  const tsah::PrimitiveBoxes rep = tsah::triangleBoxes(s.indices, s.positions, s.frames);
  Bvh bvh = tsah::SweepSahBuilder().build(rep.frame(0));
  // Frames that are not representative ones: other motions of the same triangles.
  const Scene other = randomScene(250, 6, 4);
  const tsah::PrimitiveBoxes frames = tsah::triangleBoxes(other.indices, other.positions, other.frames);
  tsah::FrameCostEvaluator evaluator(bvh, {3.0f, 2.0f});
  for (uint32_t f = 0; f < frames.frameCount; ++f) {
    Bvh copy = bvh;
    tsah::PrimitiveBoxes one;
    one.frameCount = 1;
    one.primCount = frames.primCount;
    one.boxes.assign(frames.frame(f).begin(), frames.frame(f).end());
    tsah::refit(copy, one);
    const double expected = tsah::frameCost(copy, 0);
    EXPECT_NEAR(evaluator.cost(frames.frame(f)), expected, 1e-12 * expected);
    EXPECT_EQ(evaluator.nodeBoxes()[copy.root].hi.x, copy.box(copy.root, 0).hi.x);
  }
  const std::vector<Aabb> tooFew(10);
  EXPECT_THROW(evaluator.cost(tooFew), tsah::DataError);
}

}  // namespace
