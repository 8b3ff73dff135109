// Tree quality figures (tsah/tree_quality.hpp) against cost.hpp and against brute force, on a
// hand-built tree with known numbers and on random moving triangles.
#include <gtest/gtest.h>

#include <cmath>

#include "tsah/optimize/baselines.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/inspect/tree_quality.hpp"
#include "test_support.hpp"

namespace {

using tsah::Aabb;
using tsah::Bvh;

// Collapsed SAH tree on frame 0 of random moving triangles, refitted to all frames.
struct Fixture {
  tsah::test::MovingTriangles tris = tsah::test::randomMovingTriangles(400, 5, 7, 0.4f);
  tsah::PrimitiveBoxes prims = tris.boxes();
  Bvh bvh;
  Fixture() {
    bvh = tsah::LeafCollapser(tsah::LeafCollapser::Config{}).collapse(tsah::SweepSahBuilder().build(prims.frame(0)));
    tsah::refit(bvh, prims);
  }
};

// Root over leaf A (prim 0, unit cube at the origin) and an interior node over leaves B and C
// (prims 1 and 2, unit cubes at x = 2 and x = 3); boxes per frame given by the prim boxes.
Bvh threeLeaves() {
  Bvh b;
  using tsah::kInvalidIndex;
  b.nodes = {{kInvalidIndex, 1, 2, 0, 0}, {0, kInvalidIndex, kInvalidIndex, 0, 1}, {0, 3, 4, 0, 0},
             {2, kInvalidIndex, kInvalidIndex, 1, 1}, {2, kInvalidIndex, kInvalidIndex, 2, 1}};
  b.primIds = {0, 1, 2};
  b.boxes.resize(5);
  return b;
}

Aabb cube(float x, float size = 1.0f) { return Aabb{{x, 0, 0}, {x + size, size, size}}; }

TEST(TreeQuality, CostPartsAreEquationOne) {
  Fixture s;
  tsah::FrameCostEvaluator evaluator(s.bvh);
  for (uint32_t f = 0; f < s.prims.frameCount; ++f) {
    const tsah::CostParts parts = evaluator.costParts(s.prims.frame(f));
    EXPECT_EQ(parts.total(), tsah::frameCost(s.bvh, f));  // the same sums, bit for bit
    EXPECT_NEAR(parts.inner() + parts.leaves(), parts.total(), 1e-12 * parts.total());
    EXPECT_GT(parts.inner(), 0.0);
    EXPECT_GT(parts.leaves(), 0.0);
  }
}

TEST(TreeQuality, HandBuiltTreeHasKnownFigures) {
  const Bvh b = threeLeaves();
  const tsah::TreeShape shape = tsah::treeShape(b);
  EXPECT_EQ(shape.innerCount, 2u);
  EXPECT_EQ(shape.leafCount, 3u);
  EXPECT_EQ(shape.depth, 2u);
  EXPECT_EQ(shape.leavesOfSize, (std::vector<uint32_t>{0, 3}));

  // Frame 0: A, B, C unit cubes (area 6 each); inner node [2,4]x[0,1]^2 (area 10); root [0,4] (18).
  // Frame 1: C doubles in size: [3,5]x[0,2]^2 (area 24); inner [2,5]x[0,2]^2 (32); root [0,5]x[0,2]^2 (48).
  tsah::PrimitiveBoxes prims{2, 3, {cube(0), cube(2), cube(3), cube(0), cube(2), cube(3, 2.0f)}};
  const tsah::TreeQuality q = tsah::evaluateTreeQuality(b, tsah::FrameSource::fromBoxes(prims));
  ASSERT_EQ(q.frames.size(), 2u);
  EXPECT_DOUBLE_EQ(q.frames[0].cost.inner(), 3.0 * (18 + 10) / 18);
  EXPECT_DOUBLE_EQ(q.frames[0].cost.leaves(), 2.0 * (6 + 6 + 6) / 18);
  EXPECT_DOUBLE_EQ(q.frames[1].cost.total(), (3.0 * (48 + 32) + 2.0 * (6 + 6 + 24)) / 48);
  EXPECT_DOUBLE_EQ(q.frames[0].meanLeafDepth, (6 * 1 + 6 * 2 + 6 * 2) / 18.0);
  EXPECT_DOUBLE_EQ(q.frames[1].meanLeafDepth, (6 * 1 + 6 * 2 + 24 * 2) / 36.0);
  EXPECT_DOUBLE_EQ(q.frames[1].meanLeafSize, 1.0);
  EXPECT_DOUBLE_EQ(q.frames[1].rootChildGrowth[0], 1.0);        // A does not move
  EXPECT_DOUBLE_EQ(q.frames[1].rootChildGrowth[1], 32.0 / 10);  // the inner node grows
  // Growth: largest over smallest share of the root's area. C: 24/48 over 6/18.
  EXPECT_NEAR(q.nodeGrowth[4], (24.0 / 48) / (6.0 / 18), 1e-9);
  EXPECT_NEAR(q.nodeGrowth[1], (6.0 / 18) / (6.0 / 48), 1e-9);  // A's share shrinks as the root grows
  EXPECT_NEAR(q.nodeGrowth[0], 1.0, 1e-9);                      // the root always covers itself

  const tsah::FrameBoxes f1 = tsah::frameBoxes(b, prims.frame(1));
  EXPECT_DOUBLE_EQ(f1.costShare[2], 3.0 * 32 / (3.0 * (48 + 32) + 2.0 * 36));
  EXPECT_DOUBLE_EQ(f1.costShare[4], 2.0 * 24 / (3.0 * (48 + 32) + 2.0 * 36));
}

TEST(TreeQuality, AgreesWithTheBaselineEvaluationAndBruteForce) {
  Fixture s;
  const tsah::FrameSource frames = tsah::FrameSource::fromBoxes(s.prims);
  const tsah::TreeQuality q = tsah::evaluateTreeQuality(s.bvh, frames);
  const std::vector<double> costs = tsah::evaluateFrames(s.bvh, frames, {}, 1);
  ASSERT_EQ(q.frames.size(), costs.size());
  for (std::size_t f = 0; f < costs.size(); ++f) EXPECT_EQ(q.frames[f].cost.total(), costs[f]);
  EXPECT_EQ(q.frames[0].rootChildGrowth[0], 1.0);

  // Growth of every node from the refitted boxes stored in the tree.
  for (uint32_t n = 0; n < s.bvh.nodeCount(); ++n) {
    double lo = INFINITY, hi = 0.0;
    for (uint32_t f = 0; f < s.prims.frameCount; ++f) {
      const double share = double(s.bvh.box(n, f).area()) / s.bvh.box(s.bvh.root, f).area();
      lo = std::min(lo, share);
      hi = std::max(hi, share);
    }
    EXPECT_NEAR(q.nodeGrowth[n], hi / lo, 1e-6 * hi / lo) << "node " << n;
  }

  // Cost shares of one frame add up to 1 and follow nodeCostTerm.
  const tsah::FrameBoxes fb = tsah::frameBoxes(s.bvh, s.prims.frame(3));
  double sum = 0.0;
  for (double share : fb.costShare) sum += share;
  EXPECT_NEAR(sum, 1.0, 1e-9);
  EXPECT_EQ(fb.cost.total(), tsah::frameCost(s.bvh, 3));

  const tsah::TreeShape shape = tsah::treeShape(s.bvh);
  EXPECT_EQ(shape.depth, s.bvh.depth());
  EXPECT_EQ(shape.leafCount, s.bvh.leafCount());
  EXPECT_EQ(shape.primCount, 400u);
  uint32_t leaves = 0;
  for (uint32_t count : shape.leavesOfSize) leaves += count;
  EXPECT_EQ(leaves, shape.leafCount);
}

}  // namespace
