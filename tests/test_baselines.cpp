// Baselines of the paper's Table 1: method names, frame sources, evaluation by refit, and the
// expected ordering of the methods on an animation that defeats a frame-0 tree.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/build/sah_builder.hpp"

namespace {

using tsah::Bvh;
using tsah::Method;
using tsah::MethodSpec;

struct Triangles {
  std::vector<uint32_t> indices;
  std::vector<float> positions;  // frames blocks
  uint32_t frames = 0;

  tsah::PrimitiveBoxes boxes() const { return tsah::triangleBoxes(indices, positions, frames); }
};

// Clusters of four triangles whose neighbours change after frame 0 (A-B, C-D become A-C, B-D),
// plus random triangles drifting apart over time, sampled at `frames` uniform times of [0, 1].
Triangles swapAnimation(uint32_t clusters, uint32_t frames, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> jitter(-0.05f, 0.05f);
  Triangles t;
  t.frames = frames;
  const uint32_t triangles = clusters * 4;
  for (uint32_t i = 0; i < triangles * 3; ++i) t.indices.push_back(i);
  std::vector<float> noise(triangles * 9);
  for (float& n : noise) n = jitter(rng);
  const float y0[4] = {0, 0, 5, 5}, x0[4] = {0, 1, 0, 1};
  const float y1[4] = {0, 5, 0, 5}, x1[4] = {0, 0, 1, 1};
  for (uint32_t f = 0; f < frames; ++f) {
    // Swap within the first fifth of the animation, hold the new pairs afterwards.
    const float time = frames > 1 ? float(f) / float(frames - 1) : 0.0f;
    const float s = std::min(1.0f, time * 5.0f);
    for (uint32_t c = 0; c < clusters; ++c)
      for (uint32_t q = 0; q < 4; ++q) {
        const float x = float(c) * 100.0f + (1 - s) * x0[q] + s * x1[q];
        const float y = (1 - s) * y0[q] + s * y1[q] + float(c % 3) * 20.0f;
        const float corners[3][3] = {{x, y, 0}, {x + 0.1f, y, 0}, {x, y + 0.1f, 0.1f}};
        for (uint32_t v = 0; v < 3; ++v)
          for (int a = 0; a < 3; ++a)
            t.positions.push_back(corners[v][a] + noise[(c * 4 + q) * 9 + v * 3 + uint32_t(a)]);
      }
  }
  return t;
}

TEST(Baselines, MethodNamesRoundTrip) {
  for (const char* name : {"sah0", "sahstar", "rebuild", "tsah0", "tsah2", "tsah4", "tsah10"})
    EXPECT_EQ(MethodSpec::parse(name).name(), name);
  EXPECT_EQ(MethodSpec::parse("tsah").name(), "tsah0");
  EXPECT_EQ(MethodSpec::parse("tsah2").k, 2);
  EXPECT_EQ(MethodSpec::parse("rebuild").method, Method::SahRebuild);
  for (const char* bad : {"", "sah", "tsahx", "tsah-1", "SAH0", "tsah123", "tsah17", "tsah99"})
    EXPECT_THROW(MethodSpec::parse(bad), tsah::ConfigError) << bad;
}

TEST(Baselines, FrameSourcesProduceTriangleBoxes) {
  const Triangles t = swapAnimation(3, 4, 1);
  const tsah::PrimitiveBoxes expected = t.boxes();
  const tsah::FrameSource fromTriangles = tsah::FrameSource::fromTriangles(t.indices, t.positions, t.frames);
  const tsah::FrameSource fromBoxes = tsah::FrameSource::fromBoxes(expected);
  for (const tsah::FrameSource* source : {&fromTriangles, &fromBoxes}) {
    ASSERT_EQ(source->frameCount, 4u);
    ASSERT_EQ(source->primCount, 12u);
    std::vector<tsah::Aabb> boxes(12);
    for (uint32_t f = 0; f < 4; ++f) {
      source->fill(f, boxes);
      for (uint32_t p = 0; p < 12; ++p) {
        EXPECT_EQ(boxes[p].lo.x, expected.at(f, p).lo.x);
        EXPECT_EQ(boxes[p].hi.y, expected.at(f, p).hi.y);
      }
    }
  }
}

TEST(Baselines, EvaluateFramesIsRefitPlusFrameCost) {
  const Triangles t = swapAnimation(10, 7, 2);
  const tsah::PrimitiveBoxes all = t.boxes();
  Bvh bvh = tsah::SweepSahBuilder().build(all.frame(0));
  const tsah::FrameSource source = tsah::FrameSource::fromTriangles(t.indices, t.positions, t.frames);
  const std::vector<double> one = tsah::evaluateFrames(bvh, source, {}, 1);
  const std::vector<double> two = tsah::evaluateFrames(bvh, source, {}, 2);
  EXPECT_EQ(one, two);
  tsah::refit(bvh, all);
  const std::vector<double> expected = tsah::frameCosts(bvh);
  ASSERT_EQ(one.size(), expected.size());
  for (std::size_t f = 0; f < one.size(); ++f) EXPECT_NEAR(one[f], expected[f], 1e-12 * expected[f]);

  const Triangles other = swapAnimation(11, 2, 3);
  EXPECT_THROW(tsah::evaluateFrames(bvh, tsah::FrameSource::fromTriangles(other.indices, other.positions, 2), {}),
               tsah::DataError);
}

TEST(Baselines, SingleTreeMethodsGiveValidTreesOverTheRepresentativeFrames) {
  const Triangles t = swapAnimation(12, 5, 4);
  const tsah::PrimitiveBoxes rep = t.boxes();
  for (uint32_t maxLeaf : {1u, 4u}) {
    tsah::BaselineConfig config;
    config.objective.maxLeafSize = maxLeaf;
    for (const char* name : {"sah0", "sahstar", "tsah0", "tsah2"}) {
      const Bvh bvh = tsah::buildMethod(MethodSpec::parse(name), rep, config);
      const auto problem = tsah::validate(bvh, &rep);
      ASSERT_FALSE(problem.has_value()) << name << ": " << *problem;
      EXPECT_EQ(bvh.frameCount, 5u) << name;
      for (const tsah::BvhNode& node : bvh.nodes) {
        if (node.isLeaf()) {
          EXPECT_LE(node.primCount, maxLeaf) << name;
        }
      }
    }
  }
  EXPECT_THROW(tsah::buildMethod(MethodSpec::parse("rebuild"), rep, {}), tsah::ConfigError);
}

TEST(Baselines, SahStarKeepsTheBestTreeOverTime) {
  const Triangles t = swapAnimation(12, 5, 5);
  const tsah::PrimitiveBoxes rep = t.boxes();
  tsah::BaselineConfig config;
  config.objective.maxLeafSize = 1;
  Bvh star = tsah::buildSahStar(rep, config);
  const double starAverage = tsah::temporalCost(tsah::frameCosts(star), 0);
  // Any single-frame optimized tree refitted over the frames is at best as good.
  for (uint32_t f = 0; f < rep.frameCount; ++f) {
    Bvh tree = tsah::buildOptimizedSah(rep.frame(f), config, 12345 + f);
    tsah::refit(tree, rep);
    EXPECT_LE(starAverage, tsah::temporalCost(tsah::frameCosts(tree), 0) * 1.02) << "frame " << f;
  }
  // Frames 1..4 agree on the grouping, frame 0 does not: SAH* beats SAH0.
  const Bvh sah0 = tsah::buildSah0(rep, config);
  EXPECT_LT(starAverage, 0.9 * tsah::temporalCost(tsah::frameCosts(sah0), 0));
}

TEST(Baselines, TableOneOrderingOnASwapAnimation) {
  const Triangles rep = swapAnimation(16, 5, 6);
  const Triangles evaluation = swapAnimation(16, 20, 6);
  const tsah::FrameSource source =
      tsah::FrameSource::fromTriangles(evaluation.indices, evaluation.positions, evaluation.frames);
  std::vector<MethodSpec> methods;
  for (const char* name : {"sah0", "sahstar", "tsah0", "tsah2", "rebuild"}) methods.push_back(MethodSpec::parse(name));
  tsah::BaselineConfig config;
  config.objective.maxLeafSize = 1;
  config.threads = 2;
  std::vector<std::string> messages;
  config.progress = [&](const std::string& m) { messages.push_back(m); };
  const auto results = tsah::compareMethods(methods, rep.boxes(), source, config);
  ASSERT_EQ(results.size(), methods.size());
  for (std::size_t m = 0; m < results.size(); ++m) {
    const tsah::MethodResult& r = results[m];
    EXPECT_EQ(r.name, methods[m].name());
    ASSERT_EQ(r.perFrame.size(), 20u);
    EXPECT_DOUBLE_EQ(r.maximum, *std::max_element(r.perFrame.begin(), r.perFrame.end()));
    double sum = 0;
    for (double c : r.perFrame) sum += c;
    EXPECT_NEAR(r.average, sum / 20.0, 1e-12 * r.average);
    EXPECT_GE(r.buildSeconds, 0.0);
  }
  const auto& sah0 = results[0];
  const auto& tsah0 = results[2];
  const auto& rebuild = results[4];
  EXPECT_LT(tsah0.average, 0.9 * sah0.average);
  // The per-frame rebuild is the lower bound; on frame 0 it optimizes the very tree SAH0 refits.
  EXPECT_LE(rebuild.perFrame[0], sah0.perFrame[0] * (1 + 1e-12));
  EXPECT_LE(rebuild.average, tsah0.average * 1.02);
  EXPECT_FALSE(messages.empty());

  // The thread count changes nothing.
  config.threads = 1;
  config.progress = nullptr;
  const auto serial = tsah::compareMethods(methods, rep.boxes(), source, config);
  for (std::size_t m = 0; m < results.size(); ++m) EXPECT_EQ(serial[m].perFrame, results[m].perFrame);
}

}  // namespace

// binnedInitialTree: every method starts from the binned SAH builder's tree instead of the sweep's
// (SAH0 is that tree, collapsed; with leaves of one primitive nothing collapses).
TEST(Baselines, BinnedInitialTreeStartsFromTheBinnedBuilder) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 100.0f);
  std::vector<tsah::Aabb> frame(500);
  for (tsah::Aabb& b : frame) {
    const tsah::Vec3 p{unit(rng), unit(rng), unit(rng)};
    b.lo = p;
    b.hi = p + tsah::Vec3{1.0f, 2.0f, 0.5f};
  }
  tsah::PrimitiveBoxes rep;
  rep.frameCount = 1;
  rep.primCount = uint32_t(frame.size());
  rep.boxes = frame;
  tsah::BaselineConfig config;
  config.objective.maxLeafSize = 1;
  tsah::BinnedSahBuilder::Config binned;
  binned.cost = config.objective.cost;
  binned.maxLeafSize = 1;
  const Bvh expected = tsah::BinnedSahBuilder(binned).build(frame);
  const Bvh sweep = tsah::buildSah0(rep, config);
  ASSERT_NE(sweep.primIds, expected.primIds) << "the input must tell the two builders apart";
  config.binnedInitialTree = true;
  const Bvh got = tsah::buildSah0(rep, config);
  EXPECT_EQ(got.primIds, expected.primIds);
  EXPECT_EQ(got.nodeCount(), expected.nodeCount());
  EXPECT_DOUBLE_EQ(tsah::temporalCost(tsah::frameCosts(got), 0), tsah::temporalCost(tsah::frameCosts(expected), 0));
}
