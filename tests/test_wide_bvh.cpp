// WideCollapser (wide_bvh.hpp): valid wide trees holding every triangle once with boxes that contain
// their contents in every frame, a multi-frame cost never above the binary tree's, and exactly the
// optimum of an independent brute-force enumeration on small random trees.
#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <random>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/wide_bvh.hpp"
#include "test_support.hpp"

namespace {

using tsah::Bvh;
using tsah::WideBvh;
using tsah::WideCollapser;

// A random binary tree over `prims` primitives (leaves of 1..maxLeaf, random splits), refitted to
// the frames of `boxes`.
Bvh randomTree(const tsah::PrimitiveBoxes& boxes, uint32_t maxLeaf, std::mt19937& rng) {
  Bvh bvh;
  std::vector<uint32_t> ids(boxes.primCount);
  for (uint32_t i = 0; i < ids.size(); ++i) ids[i] = i;
  std::shuffle(ids.begin(), ids.end(), rng);
  bvh.primIds = ids;
  std::function<uint32_t(uint32_t, uint32_t, uint32_t)> make = [&](uint32_t begin, uint32_t count, uint32_t parent) {
    const uint32_t n = bvh.nodeCount();
    bvh.nodes.push_back({});
    bvh.nodes[n].parent = parent;
    const uint32_t leafSize = std::uniform_int_distribution<uint32_t>(1, maxLeaf)(rng);
    if (count <= leafSize) {
      bvh.nodes[n].primBegin = begin;
      bvh.nodes[n].primCount = count;
      return n;
    }
    const uint32_t left = std::uniform_int_distribution<uint32_t>(1, count - 1)(rng);
    const uint32_t l = make(begin, left, n);
    const uint32_t r = make(begin + left, count - left, n);
    bvh.nodes[n].left = l;
    bvh.nodes[n].right = r;
    return n;
  };
  bvh.root = make(0, boxes.primCount, tsah::kInvalidIndex);
  tsah::refit(bvh, boxes);
  return bvh;
}

std::vector<double> randomWeights(uint32_t frames, std::mt19937& rng) {
  std::vector<double> w(frames);
  for (double& x : w) x = std::uniform_real_distribution<double>(0.1, 1.0)(rng);
  return w;
}

// The cheapest sum_i w_i C_i over every wide tree made of the binary tree's nodes, by enumerating
// every (cost, slot count) a subtree can hand to its parent. Independent of the collapser's DP.
double bruteForceOptimum(const Bvh& bvh, std::vector<double> weights, uint32_t width, uint32_t maxLeaf,
                         const tsah::CostModel& model, uint32_t packet) {
  double total = 0;
  for (double w : weights) total += w;
  auto area = [&](uint32_t n) {
    double a = 0;
    for (uint32_t f = 0; f < bvh.frameCount; ++f)
      a += weights[f] / total * bvh.box(n, f).area() / bvh.box(bvh.root, f).area();
    return a;
  };
  std::function<uint32_t(uint32_t)> count = [&](uint32_t n) -> uint32_t {
    const auto& node = bvh.nodes[n];
    return node.isLeaf() ? node.primCount : count(node.left) + count(node.right);
  };
  using Option = std::pair<double, uint32_t>;  // cost, slots
  std::function<std::vector<Option>(uint32_t)> options = [&](uint32_t n) {
    const auto& node = bvh.nodes[n];
    const double a = area(n);
    std::vector<Option> out;
    const double tests = double((count(n) + packet - 1) / packet);
    if (node.isLeaf() || count(n) <= maxLeaf) out.push_back({double(model.ci) * tests * a, 1});
    if (node.isLeaf()) return out;
    for (const Option& l : options(node.left))
      for (const Option& r : options(node.right)) {
        if (l.second + r.second > width) continue;
        out.push_back({model.ct * a + l.first + r.first, 1});  // n becomes a wide node
        out.push_back({l.first + r.first, l.second + r.second});  // n dissolves into its parent
      }
    return out;
  };
  double best = 1e300;
  for (const Option& o : options(bvh.root))
    if (o.second == 1) best = std::min(best, o.first);
  return best;
}

TEST(WideBvh, MatchesBruteForceOptimumOnSmallRandomTrees) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 60; ++trial) {
    const uint32_t prims = 3 + trial % 9, frames = 1 + trial % 3;
    const auto boxes = tsah::test::randomMovingTriangles(prims, frames, 100 + trial, 2.0f).boxes();
    const Bvh bvh = randomTree(boxes, 1 + trial % 3, rng);
    const std::vector<double> weights = randomWeights(frames, rng);
    for (uint32_t width : {2u, 3u, 4u, 8u})
      for (uint32_t maxLeaf : {1u, 3u, 8u}) {
        WideCollapser::Config config;
        config.width = width;
        config.maxLeafSize = maxLeaf;
        config.leafPacket = trial % 3 == 0 ? 4 : 1;
        config.cost = {trial % 2 ? 3.0f : 1.0f, 2.0f};
        double reached = 0;
        const WideBvh wide = WideCollapser(config).collapse(bvh, weights, &reached);
        ASSERT_EQ(tsah::validateWide(wide, &boxes), std::nullopt);
        const double expected = bruteForceOptimum(bvh, weights, width, maxLeaf, config.cost, config.leafPacket);
        EXPECT_NEAR(reached, expected, 1e-9 * expected) << "trial " << trial << " width " << width;
        if (config.leafPacket == 1) {  // wideWeightedCost is Eq. 1: one test per triangle
          EXPECT_NEAR(tsah::wideWeightedCost(wide, weights, config.cost), expected, 1e-5 * expected);
        }
        for (const tsah::WideChild& c : wide.children) {
          if (c.isLeaf()) {
            EXPECT_TRUE(c.count <= maxLeaf || c.count <= 3);  // 3: the largest binary leaf
          }
        }
      }
  }
}

Bvh sahTree(const tsah::PrimitiveBoxes& boxes, uint32_t maxLeaf) {
  tsah::LeafCollapser::Config c;
  c.maxLeafSize = maxLeaf;
  Bvh bvh = tsah::LeafCollapser(c).collapse(tsah::SweepSahBuilder().build(boxes.frame(0)));
  tsah::refit(bvh, boxes);
  return bvh;
}

TEST(WideBvh, EveryTriangleOnceAndBoxesContainChildrenAfterRefit) {
  const auto moving = tsah::test::randomMovingTriangles(3000, 4, 3, 2.0f);
  const auto boxes = moving.boxes();
  const Bvh bvh = sahTree(boxes, 4);
  for (uint32_t width : {4u, 8u}) {
    WideCollapser::Config config;
    config.width = width;
    WideBvh wide = WideCollapser(config).collapse(bvh);
    ASSERT_EQ(tsah::validateWide(wide, &boxes), std::nullopt);
    std::vector<uint32_t> ids = wide.primIds;
    std::sort(ids.begin(), ids.end());
    for (uint32_t i = 0; i < ids.size(); ++i) ASSERT_EQ(ids[i], i);
    EXPECT_LT(wide.nodeCount(), bvh.nodeCount() / 2);  // it did merge
    // Refit to other frames (more of them): still valid, and the boxes are tight.
    const auto later = tsah::test::randomMovingTriangles(3000, 7, 3, 2.0f).boxes();
    tsah::refitWide(wide, later);
    ASSERT_EQ(tsah::validateWide(wide, &later), std::nullopt);
    tsah::Aabb all;
    for (uint32_t p = 0; p < later.primCount; ++p) all.extend(later.at(6, p));
    EXPECT_EQ(wide.rootBoxes[6].lo.x, all.lo.x);
    EXPECT_EQ(wide.rootBoxes[6].hi.z, all.hi.z);
    const auto ends = tsah::wideSubtreeEnds(wide);
    EXPECT_EQ(ends[0], wide.nodeCount());
  }
}

TEST(WideBvh, NeverCostsMoreThanTheBinaryTree) {
  const auto boxes = tsah::test::randomMovingTriangles(2000, 5, 11, 3.0f).boxes();
  for (uint32_t leaf : {1u, 8u}) {
    const Bvh bvh = sahTree(boxes, leaf);
    for (int k : {0, 2}) {
      const tsah::CostModel model{3.0f, 2.0f};
      const double binary = tsah::temporalCost(tsah::frameCosts(bvh, model), k);
      for (uint32_t width : {2u, 4u, 8u}) {
        WideCollapser::Config config;
        config.width = width;
        config.k = k;
        const WideBvh wide = WideCollapser(config).collapse(bvh);
        const double cost = tsah::temporalCost(tsah::wideFrameCosts(wide, model), k);
        EXPECT_LE(cost, binary * (1 + 1e-9)) << "k " << k << " width " << width << " leaf " << leaf;
        if (width > 2) {
          EXPECT_LT(cost, binary) << "a wider node saves interior visits";
        }
      }
    }
  }
}

TEST(WideBvh, WholeTreeAsOneLeaf) {
  const auto boxes = tsah::test::randomMovingTriangles(3, 2, 5, 1.0f).boxes();
  const Bvh bvh = sahTree(boxes, 1);
  WideCollapser::Config config;
  config.cost = {100.0f, 0.01f};  // interior nodes very dear: one leaf is cheapest
  const WideBvh wide = WideCollapser(config).collapse(bvh);
  EXPECT_TRUE(tsah::isLeafRef(wide.rootRef));
  EXPECT_EQ(wide.rootCount, 3u);
  EXPECT_EQ(wide.depth(), 0u);
  EXPECT_EQ(tsah::validateWide(wide, &boxes), std::nullopt);
}

TEST(WideBvh, RejectsBadInputAndValidationCatchesCorruption) {
  WideCollapser::Config bad;
  bad.width = 9;
  EXPECT_THROW(WideCollapser{bad}, tsah::ConfigError);
  bad.width = 4;
  bad.maxLeafSize = 0;
  EXPECT_THROW(WideCollapser{bad}, tsah::ConfigError);
  EXPECT_THROW(WideCollapser().collapse(Bvh{}), tsah::DataError);

  const auto boxes = tsah::test::randomMovingTriangles(200, 2, 9, 1.0f).boxes();
  const Bvh bvh = sahTree(boxes, 2);
  const std::vector<double> wrongCount(3, 1.0);
  EXPECT_THROW(WideCollapser().collapse(bvh, wrongCount), tsah::ConfigError);
  const WideBvh good = WideCollapser().collapse(bvh);
  ASSERT_EQ(tsah::validateWide(good, &boxes), std::nullopt);
  WideBvh dup = good;
  dup.primIds[1] = dup.primIds[0];
  EXPECT_NE(tsah::validateWide(dup), std::nullopt);
  WideBvh shrunk = good;
  shrunk.childBoxes[0].hi.x = shrunk.childBoxes[0].lo.x - 1.0f;
  EXPECT_NE(tsah::validateWide(shrunk, &boxes), std::nullopt);
  WideBvh cycle = good;
  for (auto& c : cycle.children)
    if (!c.isLeaf()) {
      c.ref = 0;
      break;
    }
  EXPECT_NE(tsah::validateWide(cycle), std::nullopt);
}

}  // namespace
