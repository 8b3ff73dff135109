// LeafCollapser: valid compacted trees, never a higher cost, and for k = 0 exactly the optimum over
// all collapse choices (checked against an independent recursion).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <functional>
#include <random>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"
#include "test_support.hpp"

namespace {

using tsah::Bvh;
using tsah::LeafCollapser;

tsah::PrimitiveBoxes randomMovingBoxes(uint32_t triangles, uint32_t frames, uint32_t seed) {
  return tsah::test::randomMovingTriangles(triangles, frames, seed, 2.0f).boxes();
}

Bvh optimizedTree(const tsah::PrimitiveBoxes& prims, int k) {
  Bvh bvh = tsah::SweepSahBuilder().build(prims.frame(0));
  tsah::InsertionOptimizer::Config config;
  config.k = k;
  config.maxBatches = 5;
  return tsah::InsertionOptimizer(config).optimize(std::move(bvh), prims).bvh;
}

void expectCompactLayout(const Bvh& bvh) {
  EXPECT_EQ(bvh.root, 0u);
  uint32_t nextPrim = 0;
  // Depth-first, left first: leaves appear in primId order, children are adjacent.
  std::function<void(uint32_t)> visit = [&](uint32_t n) {
    const tsah::BvhNode& node = bvh.nodes[n];
    if (node.isLeaf()) {
      EXPECT_EQ(node.primBegin, nextPrim);
      nextPrim += node.primCount;
      return;
    }
    EXPECT_EQ(node.right, node.left + 1);
    EXPECT_GT(node.left, n);
    visit(node.left);
    visit(node.right);
  };
  visit(bvh.root);
  EXPECT_EQ(nextPrim, bvh.primCount());
}

// The cheapest k = 0 cost over every set of collapse choices, by plain recursion.
double optimalMeanCost(const Bvh& bvh, uint32_t maxLeaf, double ct, double ci) {
  std::vector<double> factor(bvh.frameCount);
  for (uint32_t f = 0; f < bvh.frameCount; ++f)
    factor[f] = 1.0 / (bvh.frameCount * double(bvh.box(bvh.root, f).area()));
  std::function<std::pair<double, uint32_t>(uint32_t)> best = [&](uint32_t n) -> std::pair<double, uint32_t> {
    const tsah::BvhNode& node = bvh.nodes[n];
    double area = 0;
    for (uint32_t f = 0; f < bvh.frameCount; ++f) area += factor[f] * bvh.box(n, f).area();
    if (node.isLeaf()) return {ci * node.primCount * area, node.primCount};
    const auto l = best(node.left), r = best(node.right);
    const uint32_t count = l.second + r.second;
    double cost = ct * area + l.first + r.first;
    if (count <= maxLeaf) cost = std::min(cost, ci * count * area);
    return {cost, count};
  };
  return best(bvh.root).first;
}

TEST(LeafCollapser, NeverRaisesTheCostAndKeepsTheTreeValid) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    for (int k : {0, 2, 4}) {
      for (uint32_t maxLeaf : {2u, 4u, 8u}) {
        const tsah::PrimitiveBoxes prims = randomMovingBoxes(300, 3, seed);
        const Bvh tree = optimizedTree(prims, k);
        const double before = tsah::temporalCost(tsah::frameCosts(tree), k);
        const Bvh collapsed = LeafCollapser({k, {}, maxLeaf}).collapse(tree);
        const auto problem = tsah::validate(collapsed, &prims);
        ASSERT_FALSE(problem.has_value()) << *problem;
        const double after = tsah::temporalCost(tsah::frameCosts(collapsed), k);
        EXPECT_LE(after, before * (1 + 1e-12)) << "k=" << k << " maxLeaf=" << maxLeaf;
        EXPECT_LT(collapsed.nodeCount(), tree.nodeCount());
        for (const tsah::BvhNode& node : collapsed.nodes) {
          if (node.isLeaf()) {
            EXPECT_LE(node.primCount, maxLeaf);
          }
        }
        expectCompactLayout(collapsed);
        EXPECT_EQ(collapsed.frameCount, 3u);
      }
    }
  }
}

TEST(LeafCollapser, KZeroFindsTheOptimalCollapse) {
  for (const tsah::CostModel model : {tsah::CostModel{}, tsah::CostModel{1.0f, 1.0f}, tsah::CostModel{10.0f, 1.0f}}) {
    const tsah::PrimitiveBoxes prims = randomMovingBoxes(200, 2, 9);
    const Bvh tree = optimizedTree(prims, 0);
    const Bvh collapsed = LeafCollapser({0, model, 6}).collapse(tree);
    const double after = tsah::temporalCost(tsah::frameCosts(collapsed, model), 0);
    const double optimum = optimalMeanCost(tree, 6, model.ct, model.ci);
    EXPECT_NEAR(after, optimum, 1e-9 * optimum);
  }
}

TEST(LeafCollapser, CostConstantsDecideTheLeafSize) {
  const tsah::PrimitiveBoxes prims = randomMovingBoxes(400, 1, 4);
  const Bvh tree = optimizedTree(prims, 0);
  // Expensive traversal: many primitives per leaf. Expensive intersection: hardly any collapse.
  const Bvh coarse = LeafCollapser({0, {30.0f, 1.0f}, 8}).collapse(tree);
  const Bvh fine = LeafCollapser({0, {1.0f, 30.0f}, 8}).collapse(tree);
  EXPECT_LT(coarse.leafCount(), 400u / 4);
  EXPECT_EQ(fine.leafCount(), 400u);
  // Leaf size 1 changes nothing but the numbering.
  const Bvh same = LeafCollapser({0, {}, 1}).collapse(tree);
  EXPECT_EQ(same.nodeCount(), tree.nodeCount());
  EXPECT_NEAR(tsah::frameCost(same, 0), tsah::frameCost(tree, 0), 1e-9 * tsah::frameCost(tree, 0));
}

TEST(LeafCollapser, CompactPreservesTheTree) {
  const tsah::PrimitiveBoxes prims = randomMovingBoxes(150, 2, 5);
  const Bvh tree = optimizedTree(prims, 0);
  const Bvh compacted = LeafCollapser::compact(tree);
  ASSERT_FALSE(tsah::validate(compacted, &prims).has_value());
  expectCompactLayout(compacted);
  EXPECT_EQ(compacted.nodeCount(), tree.nodeCount());
  EXPECT_EQ(compacted.depth(), tree.depth());
  const auto a = tsah::frameCosts(tree), b = tsah::frameCosts(compacted);
  for (std::size_t f = 0; f < a.size(); ++f) EXPECT_NEAR(a[f], b[f], 1e-12 * a[f]);
  // Flagging the root collapses everything into one leaf.
  std::vector<uint8_t> flags(tree.nodeCount(), 0);
  flags[tree.root] = 1;
  const Bvh one = LeafCollapser::compact(tree, flags);
  ASSERT_EQ(one.nodeCount(), 1u);
  EXPECT_EQ(one.nodes[0].primCount, 150u);
  EXPECT_FALSE(tsah::validate(one, &prims).has_value());
}

// collapseTopology over a source, then a refit from the primitives: the tree and boxes collapse()
// gives, for every k (k > 0 may retry with new weights).
TEST(LeafCollapser, TopologyFromASourceThenRefitEqualsCollapse) {
  for (int k : {0, 2, 4}) {
    for (uint32_t maxLeaf : {1u, 3u, 8u}) {
      const tsah::PrimitiveBoxes prims = randomMovingBoxes(400, 3, 20 + k);
      const Bvh tree = optimizedTree(prims, k);
      const LeafCollapser collapser({k, {}, maxLeaf});
      const Bvh expected = collapser.collapse(tree);
      Bvh topology = collapser.collapseTopology(tsah::CollapseSource::of(tree));
      EXPECT_TRUE(topology.boxes.empty());
      EXPECT_EQ(topology.frameCount, 3u);
      tsah::refit(topology, prims);
      ASSERT_EQ(topology.nodeCount(), expected.nodeCount());
      EXPECT_EQ(topology.primIds, expected.primIds);
      for (uint32_t n = 0; n < expected.nodeCount(); ++n) {
        EXPECT_EQ(topology.nodes[n].left, expected.nodes[n].left);
        EXPECT_EQ(topology.nodes[n].primCount, expected.nodes[n].primCount);
      }
      EXPECT_EQ(std::memcmp(topology.boxes.data(), expected.boxes.data(), expected.boxes.size() * sizeof(tsah::Aabb)), 0);
    }
  }
}

TEST(LeafCollapser, EmptyTreeAndBadConfig) {
  EXPECT_TRUE(LeafCollapser().collapse(Bvh{}).nodes.empty());
  EXPECT_THROW(LeafCollapser({0, {}, 0}), tsah::ConfigError);
  EXPECT_THROW(LeafCollapser({-2, {}, 8}), tsah::ConfigError);
}

}  // namespace
