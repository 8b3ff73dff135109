// Segmentation (tsah/segmentation.hpp) and the switching rule of tree sets (tsah/tree_set.hpp):
// equal-time parts, the tree of a time (boundaries and overlaps), count mode never worse than
// equal-time parts, K = 1 equal to the single tree, the budget held on every evaluation frame of
// random and real animations, determinism.
#include <gtest/gtest.h>

#include <cmath>

#include "anim/animation.hpp"
#include "anim/load.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/segmentation.hpp"

namespace {

using tsah::SegmentationConfig;
using tsah::TimeRange;

anim::Animation movingAnimation(uint32_t triangles, uint32_t frames, uint32_t seed, float speed = 2.0f) {
  const tsah::test::MovingTriangles m = tsah::test::randomMovingTriangles(triangles, frames, seed, speed);
  std::vector<double> times(frames);
  for (uint32_t f = 0; f < frames; ++f) times[f] = double(f);
  return anim::Animation(m.indices, triangles * 3, m.positions, times, "moving");
}

tsah::Timeline timelineOf(const anim::Animation& a) {
  return tsah::Timeline::fromTriangles(a.indices(), a.vertexCount(), a.startTime(), a.endTime(),
                                       [&a](double t, std::span<float> out) { a.positionsAt(t, out); });
}

SegmentationConfig smallConfig(uint32_t evalFrames) {
  SegmentationConfig c;
  c.representativeFrames = 4;
  c.evaluationFrames = evalFrames;
  c.baseline.threads = 2;
  c.method = tsah::MethodSpec::parse("tsah0");
  return c;
}

// Brute force: the cost at each of `times` with the tree that treeIndexAt picks from `ranges`.
std::vector<double> bruteForceCosts(const anim::Animation& a, const tsah::SegmentationResult& r) {
  std::vector<double> out;
  for (double t : r.times) {
    const uint32_t s = tsah::treeIndexAt(r.parts, t);
    std::vector<tsah::Aabb> boxes(a.triangleCount());
    tsah::triangleBoxes(a.indices(), a.positionsAt(t), boxes);
    out.push_back(tsah::FrameCostEvaluator(r.trees[s], tsah::CostModel{}).cost(boxes));
  }
  return out;
}

TEST(Segmentation, EqualTimeRangesCoverTheRangeWithoutGaps) {
  for (uint32_t k : {1u, 2u, 3u, 7u}) {
    const auto s = tsah::equalTimeRanges(-1.0, 5.0, k);
    ASSERT_EQ(s.size(), k);
    EXPECT_EQ(s.front().start, -1.0);
    EXPECT_EQ(s.back().end, 5.0);
    for (uint32_t i = 0; i < k; ++i) {
      EXPECT_NEAR(s[i].end - s[i].start, 6.0 / k, 1e-12);
      if (i > 0) {
        EXPECT_EQ(s[i].start, s[i - 1].end);
      }
    }
    EXPECT_FALSE(tsah::validateTimeRanges(s).has_value());
  }
  EXPECT_THROW(tsah::equalTimeRanges(0.0, 1.0, 0), tsah::ConfigError);
  EXPECT_THROW(tsah::equalTimeRanges(1.0, 0.0, 2), tsah::ConfigError);
}

TEST(Segmentation, TreeOfATimeFollowsTheRangesBoundariesIncluded) {
  const auto s = tsah::equalTimeRanges(0.0, 99.0, 3);  // [0,33] [33,66] [66,99]
  EXPECT_EQ(tsah::treeIndexAt(s, 0.0), 0u);
  EXPECT_EQ(tsah::treeIndexAt(s, std::nextafter(33.0, 0.0)), 0u);
  EXPECT_EQ(tsah::treeIndexAt(s, 33.0), 1u);  // a boundary belongs to the later part
  EXPECT_EQ(tsah::treeIndexAt(s, 66.0), 2u);
  EXPECT_EQ(tsah::treeIndexAt(s, 99.0), 2u);
  EXPECT_EQ(tsah::treeIndexAt(s, -5.0), 0u);  // outside: first / last tree
  EXPECT_EQ(tsah::treeIndexAt(s, 500.0), 2u);
  // Overlapping ranges switch at the middle of the overlap.
  const std::vector<TimeRange> o = {{0.0, 12.0}, {8.0, 30.0}, {26.0, 40.0}};
  EXPECT_EQ(tsah::switchTime(o, 0), 10.0);
  EXPECT_EQ(tsah::treeIndexAt(o, 9.999), 0u);
  EXPECT_EQ(tsah::treeIndexAt(o, 10.0), 1u);
  EXPECT_EQ(tsah::treeIndexAt(o, 27.9), 1u);
  EXPECT_EQ(tsah::treeIndexAt(o, 28.0), 2u);
  EXPECT_FALSE(tsah::validateTimeRanges(o).has_value());
}

TEST(Segmentation, RangeRulesRefuseGapsAndDisorder) {
  using V = std::vector<TimeRange>;
  EXPECT_TRUE(tsah::validateTimeRanges(V{}).has_value());
  EXPECT_TRUE(tsah::validateTimeRanges(V{{0, 1}, {1.5, 2}}).has_value());           // gap
  EXPECT_TRUE(tsah::validateTimeRanges(V{{0, 2}, {0, 3}}).has_value());             // same start
  EXPECT_TRUE(tsah::validateTimeRanges(V{{0, 3}, {1, 3}}).has_value());             // same end
  EXPECT_TRUE(tsah::validateTimeRanges(V{{1, 0}}).has_value());
  EXPECT_TRUE(tsah::validateTimeRanges(V{{0, std::nan("")}}).has_value());
  EXPECT_FALSE(tsah::validateTimeRanges(V{{2, 2}}).has_value());  // one instant is a valid set of one
}

TEST(Segmentation, OneTreeInCountModeIsTheSingleTree) {
  const anim::Animation a = movingAnimation(250, 8, 5);
  SegmentationConfig c = smallConfig(12);
  c.mode = SegmentationConfig::Mode::Count;
  c.count = 1;
  const tsah::SegmentationResult r = tsah::segmentTimeline(timelineOf(a), c);
  ASSERT_EQ(r.trees.size(), 1u);
  EXPECT_EQ(r.parts[0], (TimeRange{a.startTime(), a.endTime()}));
  const anim::Animation rep = a.resample(c.representativeFrames);
  const tsah::Bvh whole = tsah::buildTSah(tsah::triangleBoxes(rep.indices(), rep.allPositions(), rep.keyframeCount()),
                                          0, c.baseline);
  EXPECT_EQ(r.trees[0].primIds, whole.primIds);
  EXPECT_EQ(r.trees[0].boxes.size(), whole.boxes.size());
  const std::vector<double> direct =
      tsah::evaluateFrames(whole, timelineOf(a).frames(a.uniformTimes(c.evaluationFrames)), c.baseline.objective.cost, 1);
  ASSERT_EQ(r.costs.size(), direct.size());
  for (std::size_t i = 0; i < direct.size(); ++i) EXPECT_NEAR(r.costs[i], direct[i], 1e-9 * direct[i]);
}

TEST(Segmentation, CountModeIsNeverWorseThanEqualTimeParts) {
  for (uint32_t seed : {3u, 11u}) {
    const anim::Animation a = movingAnimation(200, 10, seed);
    for (int k : {0, 2}) {
      for (uint32_t count : {2u, 3u}) {
        SegmentationConfig c = smallConfig(16);
        c.method.k = k;
        c.mode = SegmentationConfig::Mode::Count;
        c.count = count;
        c.maxPasses = 2;
        const tsah::SegmentationResult best = tsah::segmentTimeline(timelineOf(a), c);
        const tsah::SegmentationResult equal =
            tsah::evaluateParts(timelineOf(a), tsah::equalTimeRanges(a.startTime(), a.endTime(), count), c);
        ASSERT_EQ(best.trees.size(), count);
        EXPECT_FALSE(tsah::validateTimeRanges(best.parts).has_value());
        if (k == 0) {
          EXPECT_LE(best.average, equal.average * (1 + 1e-12)) << "seed " << seed << " K " << count;
        } else {
          EXPECT_LE(best.maximum, equal.maximum * (1 + 1e-12)) << "seed " << seed << " K " << count;
        }
        const std::vector<double> brute = bruteForceCosts(a, best);
        for (std::size_t i = 0; i < brute.size(); ++i) EXPECT_NEAR(best.costs[i], brute[i], 1e-9 * brute[i]);
      }
    }
  }
}

void expectBudgetHolds(const anim::Animation& a, const tsah::SegmentationResult& r) {
  ASSERT_EQ(r.bound.size(), r.times.size());
  EXPECT_TRUE(r.budgetMet);
  const std::vector<double> brute = bruteForceCosts(a, r);
  for (std::size_t f = 0; f < r.times.size(); ++f) {
    EXPECT_NEAR(r.costs[f], brute[f], 1e-9 * brute[f]);
    EXPECT_LE(brute[f], r.bound[f]) << "evaluation frame " << f << " at t " << r.times[f];
  }
  EXPECT_FALSE(tsah::validateTimeRanges(r.parts).has_value());
  EXPECT_EQ(r.parts.front().start, a.startTime());
  EXPECT_EQ(r.parts.back().end, a.endTime());
}

TEST(Segmentation, AbsoluteBudgetHoldsOnEveryEvaluationFrameWithFewTrees) {
  for (uint32_t seed : {2u, 9u}) {
    const anim::Animation a = movingAnimation(200, 10, seed);
    SegmentationConfig c = smallConfig(15);
    c.mode = SegmentationConfig::Mode::Count;
    c.count = 1;
    const tsah::SegmentationResult one = tsah::segmentTimeline(timelineOf(a), c);
    // A bound the single tree meets: one tree is enough.
    c.mode = SegmentationConfig::Mode::Budget;
    c.budgetRelative = false;
    c.budget = one.maximum * 1.0001;
    const tsah::SegmentationResult loose = tsah::segmentTimeline(timelineOf(a), c);
    EXPECT_EQ(loose.trees.size(), 1u);
    expectBudgetHolds(a, loose);
    // A bound between the single tree's average and its peak needs more trees, and gets them.
    c.budget = 0.5 * (one.average + one.maximum);
    const tsah::SegmentationResult tight = tsah::segmentTimeline(timelineOf(a), c);
    EXPECT_GE(tight.trees.size(), 2u);
    expectBudgetHolds(a, tight);
  }
}

TEST(Segmentation, RelativeBudgetHoldsAgainstPerFrameOptimizedTrees) {
  const anim::Animation a = movingAnimation(150, 9, 4, 1.0f);
  SegmentationConfig c = smallConfig(10);
  c.budget = 1.3;
  c.referenceFrames = 0;  // every evaluation frame
  const tsah::SegmentationResult r = tsah::segmentTimeline(timelineOf(a), c);
  ASSERT_EQ(r.reference.size(), r.times.size());
  for (std::size_t f = 0; f < r.times.size(); ++f) {
    EXPECT_GT(r.reference[f], 0.0);
    EXPECT_DOUBLE_EQ(r.bound[f], 1.3 * r.reference[f]);
  }
  expectBudgetHolds(a, r);
  // The same search twice: the same parts (deterministic for a seed).
  const tsah::SegmentationResult again = tsah::segmentTimeline(timelineOf(a), c);
  EXPECT_EQ(again.parts, r.parts);
  EXPECT_EQ(again.costs, r.costs);
  // A given reference is used as it is.
  c.referenceCosts = r.reference;
  const tsah::SegmentationResult given = tsah::segmentTimeline(timelineOf(a), c);
  EXPECT_EQ(given.parts, r.parts);
  EXPECT_EQ(given.referenceSeconds, given.referenceSeconds);
}

TEST(Segmentation, OverlapWidensEachTreesBuildRangeAndKeepsTheSwitchAtTheBoundary) {
  const anim::Animation a = movingAnimation(120, 9, 6);
  SegmentationConfig c = smallConfig(9);
  c.mode = SegmentationConfig::Mode::Count;
  c.count = 3;
  c.maxPasses = 1;
  c.overlap = 0.5;
  const tsah::SegmentationResult r = tsah::segmentTimeline(timelineOf(a), c);
  ASSERT_EQ(r.buildRanges.size(), 3u);
  EXPECT_FALSE(tsah::validateTimeRanges(r.buildRanges).has_value());
  for (uint32_t s = 0; s + 1 < 3; ++s) {
    EXPECT_NEAR(r.buildRanges[s].end - r.buildRanges[s + 1].start, 0.5, 1e-12);
    EXPECT_NEAR(tsah::switchTime(r.buildRanges, s), r.parts[s].end, 1e-12);
  }
  EXPECT_EQ(r.buildRanges.front().start, a.startTime());
  EXPECT_EQ(r.buildRanges.back().end, a.endTime());
  c.overlap = 5.0;  // longer than an equal-time part
  EXPECT_THROW(tsah::segmentTimeline(timelineOf(a), c), tsah::ConfigError);
}

TEST(Segmentation, RefusesBadConfigurations) {
  const anim::Animation a = movingAnimation(40, 4, 1);
  SegmentationConfig c = smallConfig(5);
  c.method = tsah::MethodSpec::parse("rebuild");
  EXPECT_THROW(tsah::segmentTimeline(timelineOf(a), c), tsah::ConfigError);
  c = smallConfig(1);
  EXPECT_THROW(tsah::segmentTimeline(timelineOf(a), c), tsah::ConfigError);
  c = smallConfig(5);
  c.mode = SegmentationConfig::Mode::Count;
  c.count = 0;
  EXPECT_THROW(tsah::segmentTimeline(timelineOf(a), c), tsah::ConfigError);
  const anim::Animation still = a.resample(1);
  EXPECT_THROW(tsah::segmentTimeline(timelineOf(still), smallConfig(5)), tsah::DataError);
}

// Real data (skips without the data folder): an MD2 character at a 1.05x budget on a few frames.
TEST(Segmentation, BudgetHoldsOnARealAnimation) {
  const auto file = tsah::test::dataDir() / "md2" / "faerie.md2";
  if (!std::filesystem::exists(file)) GTEST_SKIP() << "no " << file;
  const anim::Animation full = anim::load(file.string());
  const anim::Animation a = full.segment(full.startTime(), full.startTime() + 0.25 * (full.endTime() - full.startTime()));
  SegmentationConfig c = smallConfig(12);
  c.budget = 1.05;
  c.referenceFrames = 0;
  c.maxPasses = 1;
  const tsah::SegmentationResult r = tsah::segmentTimeline(timelineOf(a), c);
  expectBudgetHolds(a, r);
}

// Candidate trees dealt to workers (ThreadDealer: the path of --devices and MPI ranks, whose
// candidates also travel as bytes): the same trees, parts and costs as the search on its own, in
// both modes; only the count of candidates built may grow (speculative builds).
TEST(Segmentation, DealtCandidatesGiveTheSameTreeSet) {
  const anim::Animation a = movingAnimation(200, 10, 9);
  for (const auto mode : {SegmentationConfig::Mode::Count, SegmentationConfig::Mode::Budget}) {
    SegmentationConfig c = smallConfig(15);
    c.mode = mode;
    c.count = 3;
    c.budget = 1.2;
    c.referenceFrames = 5;
    const tsah::SegmentationResult alone = tsah::segmentTimeline(timelineOf(a), c);
    for (unsigned workers : {1u, 3u}) {
      tsah::ThreadDealer dealer(workers);
      c.dealer = &dealer;
      const tsah::SegmentationResult dealt = tsah::segmentTimeline(timelineOf(a), c);
      EXPECT_EQ(dealt.parts, alone.parts);
      EXPECT_EQ(dealt.costs, alone.costs);
      EXPECT_EQ(dealt.reference, alone.reference);
      EXPECT_EQ(dealt.methods, alone.methods);
      ASSERT_EQ(dealt.trees.size(), alone.trees.size());
      for (std::size_t s = 0; s < alone.trees.size(); ++s) {
        EXPECT_EQ(dealt.trees[s].root, alone.trees[s].root);
        EXPECT_EQ(dealt.trees[s].primIds, alone.trees[s].primIds);
        ASSERT_EQ(dealt.trees[s].nodes.size(), alone.trees[s].nodes.size());
        for (std::size_t n = 0; n < alone.trees[s].nodes.size(); ++n) {
          EXPECT_EQ(dealt.trees[s].nodes[n].left, alone.trees[s].nodes[n].left);
          EXPECT_EQ(dealt.trees[s].nodes[n].primCount, alone.trees[s].nodes[n].primCount);
        }
        EXPECT_EQ(dealt.optimizations[s].finalCost, alone.optimizations[s].finalCost);
      }
      if (workers == 1) EXPECT_EQ(dealt.treesBuilt, alone.treesBuilt);  // one worker: nothing speculative
      else EXPECT_GE(dealt.treesBuilt, alone.treesBuilt);
    }
  }
}

}  // namespace
