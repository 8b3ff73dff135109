// Segmenting an animation into equal-time parts with one tree each (bench/segments.hpp).
#include <gtest/gtest.h>

#include <cmath>

#include "anim/generators.hpp"
#include "bench/segments.hpp"
#include "test_support.hpp"
#include "tsah/cost.hpp"

namespace {

using tsah::bench::TimeSegment;

TEST(BenchSegments, EqualTimeSegmentsCoverTheRangeWithoutGaps) {
  for (uint32_t k : {1u, 2u, 3u, 7u}) {
    const auto s = tsah::bench::equalTimeSegments(-1.0, 5.0, k);
    ASSERT_EQ(s.size(), k);
    EXPECT_EQ(s.front().start, -1.0);
    EXPECT_EQ(s.back().end, 5.0);  // exactly, despite rounding
    for (uint32_t i = 0; i < k; ++i) {
      EXPECT_NEAR(s[i].end - s[i].start, 6.0 / k, 1e-12);
      if (i > 0) {
        EXPECT_EQ(s[i].start, s[i - 1].end);  // consecutive: no gap, no overlap
      }
    }
  }
  const auto point = tsah::bench::equalTimeSegments(2.0, 2.0, 3);
  for (const TimeSegment& s : point) EXPECT_EQ(s.start, s.end);
  EXPECT_THROW(tsah::bench::equalTimeSegments(0.0, 1.0, 0), std::invalid_argument);
  EXPECT_THROW(tsah::bench::equalTimeSegments(1.0, 0.0, 2), std::invalid_argument);
  EXPECT_THROW(tsah::bench::equalTimeSegments(0.0, std::nan(""), 2), std::invalid_argument);
}

TEST(BenchSegments, SegmentOfPutsBoundariesIntoTheLaterPartAndClampsOutside) {
  const auto s = tsah::bench::equalTimeSegments(0.0, 99.0, 3);  // [0,33) [33,66) [66,99]
  EXPECT_EQ(tsah::bench::segmentOf(s, 0.0), 0u);
  EXPECT_EQ(tsah::bench::segmentOf(s, 32.999), 0u);
  EXPECT_EQ(tsah::bench::segmentOf(s, 33.0), 1u);
  EXPECT_EQ(tsah::bench::segmentOf(s, 65.9), 1u);
  EXPECT_EQ(tsah::bench::segmentOf(s, 66.0), 2u);
  EXPECT_EQ(tsah::bench::segmentOf(s, 99.0), 2u);
  EXPECT_EQ(tsah::bench::segmentOf(s, -5.0), 0u);
  EXPECT_EQ(tsah::bench::segmentOf(s, 500.0), 2u);
}

TEST(BenchSegments, SegmentPathGoesBeforeTheExtension) {
  EXPECT_EQ(tsah::bench::segmentPath("out/museum.tbvh", 0), "out/museum_seg0.tbvh");
  EXPECT_EQ(tsah::bench::segmentPath("a.b/tree.v2.tbvh", 12), "a.b/tree.v2_seg12.tbvh");
  EXPECT_EQ(tsah::bench::segmentPath("tree", 1), "tree_seg1");
  EXPECT_EQ(tsah::bench::segmentPath("dir.d/tree", 2), "dir.d/tree_seg2");
  EXPECT_EQ(tsah::bench::segmentPath("/x/.hidden", 3), "/x/.hidden_seg3");
}

anim::Animation movingAnimation(uint32_t triangles, uint32_t frames, uint32_t seed) {
  const tsah::test::MovingTriangles m = tsah::test::randomMovingTriangles(triangles, frames, seed, 2.0f);
  std::vector<double> times(frames);
  for (uint32_t f = 0; f < frames; ++f) times[f] = double(f);
  return anim::Animation(m.indices, triangles * 3, m.positions, times, "moving");
}

TEST(BenchSegments, EachTreeIsValidForItsPartAndEvaluationUsesTheTreeOfTheFrame) {
  const anim::Animation a = movingAnimation(400, 12, 7);
  tsah::BaselineConfig config;
  config.threads = 2;
  const uint32_t k = 3, frames = 4;
  const auto trees = tsah::bench::buildSegmentTrees(a, k, frames, tsah::MethodSpec::parse("tsah0"), config);
  ASSERT_EQ(trees.size(), k);
  std::vector<TimeSegment> parts;
  for (uint32_t s = 0; s < k; ++s) {
    const auto& t = trees[s];
    parts.push_back(t.segment);
    EXPECT_EQ(t.representativeFrames, frames);
    EXPECT_EQ(t.bvh.frameCount, frames);
    // The tree's boxes are those of the part's own representative frames.
    const anim::Animation rep = a.segment(t.segment.start, t.segment.end).resample(frames);
    const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(rep.indices(), rep.allPositions(), frames);
    EXPECT_FALSE(tsah::validate(t.bvh, &boxes).has_value());
    EXPECT_GT(t.optimization.history.size(), 0u);
    EXPECT_LE(t.optimization.finalCost, t.optimization.initialCost);
  }
  // Brute force: each time's cost with the tree of its part.
  const std::vector<double> times = a.uniformTimes(23);
  const std::vector<double> costs = tsah::bench::evaluateSegmentTrees(a, trees, times, config.cost, 2);
  ASSERT_EQ(costs.size(), times.size());
  for (std::size_t i = 0; i < times.size(); ++i) {
    const uint32_t s = tsah::bench::segmentOf(parts, times[i]);
    tsah::FrameCostEvaluator eval(trees[s].bvh, config.cost);
    std::vector<tsah::Aabb> boxes(a.triangleCount());
    tsah::triangleBoxes(a.indices(), a.positionsAt(times[i]), boxes);
    EXPECT_NEAR(costs[i], eval.cost(boxes), 1e-9 * costs[i]) << "time " << times[i];
  }
}

TEST(BenchSegments, OnePartIsTheSingleTreeAndMorePartsFitAFastMotionBetter) {
  const anim::Animation a = movingAnimation(300, 10, 3);
  tsah::BaselineConfig config;
  config.threads = 1;
  const tsah::MethodSpec tsah0 = tsah::MethodSpec::parse("tsah0");
  const std::vector<double> times = a.uniformTimes(30);
  // K = 1 builds exactly the tree of the whole animation (same frames, same seed).
  const auto one = tsah::bench::buildSegmentTrees(a, 1, 5, tsah0, config);
  const anim::Animation rep = a.resample(5);
  const tsah::Bvh whole = tsah::buildTSah(tsah::triangleBoxes(rep.indices(), rep.allPositions(), 5), 0, config);
  EXPECT_EQ(one[0].bvh.primIds, whole.primIds);
  EXPECT_EQ(one[0].bvh.boxes.size(), whole.boxes.size());
  const std::vector<double> oneCosts = tsah::bench::evaluateSegmentTrees(a, one, times, config.cost, 1);
  tsah::FrameSource source;
  source.frameCount = static_cast<uint32_t>(times.size());
  source.primCount = a.triangleCount();
  source.fill = [&](uint32_t f, std::span<tsah::Aabb> out) { tsah::triangleBoxes(a.indices(), a.positionsAt(times[f]), out); };
  const std::vector<double> direct = tsah::evaluateFrames(whole, source, config.cost, 1);
  for (std::size_t i = 0; i < times.size(); ++i) EXPECT_NEAR(oneCosts[i], direct[i], 1e-9 * direct[i]);
  // Triangles flying apart in random directions: trees for thirds of the motion are clearly better
  // on average than one tree for all of it.
  const auto three = tsah::bench::buildSegmentTrees(a, 3, 5, tsah0, config);
  const std::vector<double> threeCosts = tsah::bench::evaluateSegmentTrees(a, three, times, config.cost, 1);
  double sumOne = 0.0, sumThree = 0.0;
  for (std::size_t i = 0; i < times.size(); ++i) {
    sumOne += oneCosts[i];
    sumThree += threeCosts[i];
  }
  EXPECT_LT(sumThree, 0.95 * sumOne);
}

TEST(BenchSegments, RefusesRebuildAndStaticInput) {
  const anim::Animation a = movingAnimation(50, 4, 1);
  tsah::BaselineConfig config;
  EXPECT_THROW(tsah::bench::buildSegmentTrees(a, 2, 3, tsah::MethodSpec::parse("rebuild"), config),
               std::invalid_argument);
  const anim::Animation still = a.resample(1);
  EXPECT_THROW(tsah::bench::buildSegmentTrees(still, 2, 3, tsah::MethodSpec::parse("tsah0"), config),
               std::invalid_argument);
  EXPECT_THROW(tsah::bench::buildSegmentTrees(a, 0, 3, tsah::MethodSpec::parse("sah0"), config), std::invalid_argument);
}

}  // namespace
