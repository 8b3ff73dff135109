// SweepSahBuilder: tree invariants, and every split is the best SAH split among all sorted-centroid
// splits on all three axes (checked by brute force at every interior node).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/build/sah_builder.hpp"

namespace {

using tsah::Aabb;
using tsah::Bvh;
using tsah::Vec3;

std::vector<Aabb> randomBoxes(uint32_t count, uint32_t seed, float spread = 100.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(0.0f, spread), size(0.01f, 3.0f);
  std::vector<Aabb> boxes(count);
  for (Aabb& b : boxes) {
    const Vec3 lo{pos(rng), pos(rng), pos(rng)};
    b.lo = lo;
    b.hi = lo + Vec3{size(rng), size(rng), size(rng)};
  }
  return boxes;
}

tsah::PrimitiveBoxes asPrimitiveBoxes(const std::vector<Aabb>& boxes) {
  tsah::PrimitiveBoxes prims;
  prims.frameCount = 1;
  prims.primCount = static_cast<uint32_t>(boxes.size());
  prims.boxes = boxes;
  return prims;
}

void collectPrims(const Bvh& bvh, uint32_t n, std::vector<uint32_t>& out) {
  const tsah::BvhNode& node = bvh.nodes[n];
  if (node.isLeaf()) {
    for (uint32_t i = 0; i < node.primCount; ++i) out.push_back(bvh.primIds[node.primBegin + i]);
    return;
  }
  collectPrims(bvh, node.left, out);
  collectPrims(bvh, node.right, out);
}

double splitCost(const std::vector<Aabb>& boxes, const std::vector<uint32_t>& left,
                 const std::vector<uint32_t>& right) {
  Aabb l, r;
  for (uint32_t p : left) l.extend(boxes[p]);
  for (uint32_t p : right) r.extend(boxes[p]);
  return double(l.area()) * double(left.size()) + double(r.area()) * double(right.size());
}

// The smallest SAH split cost over every axis and every position of the centroid order.
double bestSweepCost(const std::vector<Aabb>& boxes, std::vector<uint32_t> prims) {
  double best = std::numeric_limits<double>::infinity();
  for (int axis = 0; axis < 3; ++axis) {
    std::sort(prims.begin(), prims.end(), [&](uint32_t a, uint32_t b) {
      const float ca = boxes[a].center()[axis], cb = boxes[b].center()[axis];
      return ca < cb || (ca == cb && a < b);
    });
    for (std::size_t i = 1; i < prims.size(); ++i) {
      const std::vector<uint32_t> left(prims.begin(), prims.begin() + std::ptrdiff_t(i));
      const std::vector<uint32_t> right(prims.begin() + std::ptrdiff_t(i), prims.end());
      best = std::min(best, splitCost(boxes, left, right));
    }
  }
  return best;
}

TEST(SweepSahBuilder, EmptyInputGivesEmptyTree) {
  const Bvh bvh = tsah::SweepSahBuilder().build({});
  EXPECT_TRUE(bvh.nodes.empty());
  EXPECT_FALSE(tsah::validate(bvh).has_value());
}

TEST(SweepSahBuilder, SinglePrimitiveIsOneLeaf) {
  const auto boxes = randomBoxes(1, 3);
  const Bvh bvh = tsah::SweepSahBuilder().build(boxes);
  ASSERT_EQ(bvh.nodeCount(), 1u);
  EXPECT_TRUE(bvh.nodes[0].isLeaf());
  const auto prims = asPrimitiveBoxes(boxes);
  EXPECT_FALSE(tsah::validate(bvh, &prims).has_value());
}

TEST(SweepSahBuilder, ValidTreeWithOnePrimitivePerLeaf) {
  for (uint32_t count : {2u, 3u, 17u, 500u, 3000u}) {
    const auto boxes = randomBoxes(count, count);
    const Bvh bvh = tsah::SweepSahBuilder().build(boxes);
    const auto prims = asPrimitiveBoxes(boxes);
    const auto problem = tsah::validate(bvh, &prims);
    ASSERT_FALSE(problem.has_value()) << *problem;
    EXPECT_EQ(bvh.nodeCount(), 2 * count - 1);
    EXPECT_EQ(bvh.leafCount(), count);
    EXPECT_EQ(bvh.frameCount, 1u);
    EXPECT_EQ(bvh.root, 0u);
    for (const tsah::BvhNode& node : bvh.nodes) {
      if (node.isLeaf()) {
        EXPECT_EQ(node.primCount, 1u);
      } else {
        EXPECT_EQ(node.right, node.left + 1);  // children adjacent
      }
    }
    // Boxes are exact: each node box is the union of its children (not merely containing them).
    for (uint32_t n = 0; n < bvh.nodeCount(); ++n) {
      const tsah::BvhNode& node = bvh.nodes[n];
      const Aabb expected = node.isLeaf() ? boxes[bvh.primIds[node.primBegin]]
                                          : tsah::merge(bvh.box(node.left, 0), bvh.box(node.right, 0));
      EXPECT_EQ(bvh.box(n, 0).lo.x, expected.lo.x);
      EXPECT_EQ(bvh.box(n, 0).hi.z, expected.hi.z);
    }
  }
}

TEST(SweepSahBuilder, EverySplitIsTheBestSweepSplit) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    const auto boxes = randomBoxes(120, seed, 30.0f);
    const Bvh bvh = tsah::SweepSahBuilder().build(boxes);
    for (const tsah::BvhNode& node : bvh.nodes) {
      if (node.isLeaf()) continue;
      std::vector<uint32_t> left, right, all;
      collectPrims(bvh, node.left, left);
      collectPrims(bvh, node.right, right);
      all = left;
      all.insert(all.end(), right.begin(), right.end());
      const double chosen = splitCost(boxes, left, right);
      const double best = bestSweepCost(boxes, all);
      EXPECT_LE(chosen, best * (1.0 + 1e-6)) << "a split is worse than the best sweep split";
    }
  }
}

TEST(SweepSahBuilder, IdenticalBoxesGiveABalancedTree) {
  std::vector<Aabb> boxes(1024, Aabb{{0, 0, 0}, {1, 1, 1}});
  const Bvh bvh = tsah::SweepSahBuilder().build(boxes);
  const auto prims = asPrimitiveBoxes(boxes);
  EXPECT_FALSE(tsah::validate(bvh, &prims).has_value());
  EXPECT_EQ(bvh.depth(), 10u);
}

TEST(SweepSahBuilder, LargerLeavesWhenAllowed) {
  const auto boxes = randomBoxes(2000, 11);
  tsah::SweepSahBuilder::Config config;
  config.maxLeafSize = 4;
  config.cost = {1.0f, 1.0f};  // cheap traversal: leaves are still made when they pay
  const Bvh bvh = tsah::SweepSahBuilder(config).build(boxes);
  const auto prims = asPrimitiveBoxes(boxes);
  ASSERT_FALSE(tsah::validate(bvh, &prims).has_value());
  uint32_t largest = 0;
  for (const tsah::BvhNode& node : bvh.nodes)
    if (node.isLeaf()) largest = std::max(largest, node.primCount);
  EXPECT_LE(largest, 4u);
  config.cost = {100.0f, 1.0f};  // expensive traversal: leaves of up to 4 everywhere
  const Bvh coarse = tsah::SweepSahBuilder(config).build(boxes);
  EXPECT_LT(coarse.leafCount(), bvh.leafCount());
  EXPECT_LE(coarse.leafCount(), 2000u);
  EXPECT_GE(coarse.leafCount(), 500u);
}

TEST(SweepSahBuilder, RejectsNonFiniteBoxes) {
  auto boxes = randomBoxes(10, 5);
  boxes[7].hi.y = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(tsah::SweepSahBuilder().build(boxes), tsah::DataError);
  boxes[7].hi.y = std::numeric_limits<float>::infinity();
  EXPECT_THROW(tsah::SweepSahBuilder().build(boxes), tsah::DataError);
}

TEST(SweepSahBuilder, Deterministic) {
  const auto boxes = randomBoxes(700, 9);
  const Bvh a = tsah::SweepSahBuilder().build(boxes);
  const Bvh b = tsah::SweepSahBuilder().build(boxes);
  EXPECT_EQ(a.primIds, b.primIds);
  EXPECT_EQ(tsah::frameCost(a, 0), tsah::frameCost(b, 0));
}

}  // namespace
