// The binned SAH builder: valid trees with bounded leaves, independent of the thread count and of
// the parallel threshold, sensible quality next to the full-sweep builder, bad input rejected.
#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <cmath>
#include <limits>
#include <random>

#include "anim/generators.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/build/sah_builder.hpp"
#include "test_support.hpp"

namespace {

using tsah::test::generatedAnimation;

using tsah::test::keyframeBoxes;

tsah::PrimitiveBoxes asPrimitiveBoxes(const std::vector<tsah::Aabb>& boxes) {
  tsah::PrimitiveBoxes p;
  p.frameCount = 1;
  p.primCount = static_cast<uint32_t>(boxes.size());
  p.boxes = boxes;
  return p;
}

uint32_t largestLeaf(const tsah::Bvh& bvh) {
  uint32_t m = 0;
  for (const auto& n : bvh.nodes)
    if (n.isLeaf()) m = std::max(m, n.primCount);
  return m;
}

TEST(BinnedSahBuilder, ValidTreesWithBoundedLeaves) {
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave, anim::GeneratorKind::Swap}) {
    const auto a = generatedAnimation(kind, 5000, 3);
    const auto boxes = keyframeBoxes(a, 1);
    for (uint32_t maxLeaf : {1u, 4u, 8u}) {
      tsah::BinnedSahBuilder::Config c;
      c.maxLeafSize = maxLeaf;
      const tsah::Bvh bvh = tsah::BinnedSahBuilder(c).build(boxes);
      const auto prims = asPrimitiveBoxes(boxes);
      const auto problem = tsah::validate(bvh, &prims);
      ASSERT_FALSE(problem) << *problem;
      EXPECT_EQ(bvh.root, 0u);
      EXPECT_LE(largestLeaf(bvh), maxLeaf);
      EXPECT_EQ(bvh.frameCount, 1u);
      // Children adjacent, as documented.
      for (const auto& n : bvh.nodes)
        if (!n.isLeaf()) {
          EXPECT_EQ(n.right, n.left + 1);
        }
    }
  }
}

TEST(BinnedSahBuilder, ResultDoesNotDependOnThreadsOrThreshold) {
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 20000, 2);
  const auto boxes = keyframeBoxes(a, 1);
  tsah::BinnedSahBuilder::Config c;
  c.parallelThreshold = 500;  // many tasks, parallel binning at the top
  tsah::Bvh one, many;
  tbb::task_arena(1).execute([&] { one = tsah::BinnedSahBuilder(c).build(boxes); });
  tbb::task_arena(2).execute([&] { many = tsah::BinnedSahBuilder(c).build(boxes); });
  EXPECT_TRUE(tsah::test::identicalTree(one, many));
  // A different task split gives the same tree up to node numbering: compare the SAH cost.
  c.parallelThreshold = 1u << 30;
  const tsah::Bvh serial = tsah::BinnedSahBuilder(c).build(boxes);
  EXPECT_EQ(serial.nodes.size(), one.nodes.size());
  EXPECT_DOUBLE_EQ(tsah::frameCost(serial, 0), tsah::frameCost(one, 0));
}

TEST(BinnedSahBuilder, QualityCloseToFullSweep) {
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave}) {
    const auto a = generatedAnimation(kind, 8000, 2);
    const auto boxes = keyframeBoxes(a, 0);
    tsah::BinnedSahBuilder::Config c;
    c.maxLeafSize = 1;  // compare like with like: one triangle per leaf
    const double binned = tsah::frameCost(tsah::BinnedSahBuilder(c).build(boxes), 0);
    const double sweep = tsah::frameCost(tsah::SweepSahBuilder().build(boxes), 0);
    EXPECT_LT(binned, sweep * 1.15) << anim::generatorName(kind);
    EXPECT_GT(binned, sweep * 0.85) << anim::generatorName(kind);
  }
}

TEST(BinnedSahBuilder, DegenerateInputs) {
  tsah::BinnedSahBuilder::Config c;
  c.maxLeafSize = 4;
  const tsah::BinnedSahBuilder builder(c);
  EXPECT_TRUE(builder.build({}).nodes.empty());
  // All boxes identical: no spatial split exists; leaves still respect the limit.
  tsah::Aabb b;
  b.extend(tsah::Vec3{1, 2, 3});
  b.extend(tsah::Vec3{1.5f, 2, 3});
  std::vector<tsah::Aabb> same(37, b);
  const tsah::Bvh bvh = builder.build(same);
  const auto prims = asPrimitiveBoxes(same);
  EXPECT_FALSE(tsah::validate(bvh, &prims));
  EXPECT_LE(largestLeaf(bvh), 4u);
  // A single primitive: one leaf.
  const tsah::Bvh single = builder.build(std::vector<tsah::Aabb>{b});
  ASSERT_EQ(single.nodes.size(), 1u);
  EXPECT_EQ(single.nodes[0].primCount, 1u);
}

TEST(BinnedSahBuilder, RejectsBadInput) {
  tsah::Aabb bad;
  bad.extend(tsah::Vec3{0, 0, 0});
  bad.hi.x = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(tsah::BinnedSahBuilder().build(std::vector<tsah::Aabb>{bad}), tsah::DataError);
  EXPECT_THROW(tsah::BinnedSahBuilder().build(std::vector<tsah::Aabb>{tsah::Aabb{}}), tsah::DataError);
  tsah::BinnedSahBuilder::Config c;
  c.binCount = 1;
  tsah::Aabb ok;
  ok.extend(tsah::Vec3{0, 0, 0});
  EXPECT_THROW(tsah::BinnedSahBuilder(c).build(std::vector<tsah::Aabb>{ok}), tsah::ConfigError);
  c = {};
  c.maxLeafSize = 0;
  EXPECT_THROW(tsah::BinnedSahBuilder(c).build(std::vector<tsah::Aabb>{ok}), tsah::ConfigError);
}

}  // namespace
