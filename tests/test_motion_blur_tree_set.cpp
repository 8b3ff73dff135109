// Motion blur with a tree set (CPU runtime, every layout): a shutter that crosses the set's switch
// time is traced in parts, each ray by the tree of its time; shutterStretches cuts the shutter.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <span>
#include <random>
#include <vector>

#include "anim/generators.hpp"
#include "shutter_checks.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace {

using tsah::CpuRuntime;
using tsah::Hit;
using tsah::Ray;
using tsah::test::LayoutCase;

// Six keyframes; two trees of different topology (SAH over the first and over the last keyframe);
// the set hands over between keyframes 2 and 3.
struct SetScene {
  anim::Animation animation = tsah::test::generatedAnimation(anim::GeneratorKind::Swap, 1200, 6, 7);
  tsah::FlatBvh first = tree(0), last = tree(5);
  double cut = 0.4 * time(2) + 0.6 * time(3);
  double open = 0.5 * (time(1) + time(2));
  double close = 0.3 * time(3) + 0.7 * time(4);

  double time(uint32_t k) const { return animation.times()[k]; }
  tsah::FlatBvh tree(uint32_t k) const {
    return tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(animation, k)));
  }
  // The set {a, b} handing over at `cut` (switchTime is the middle of the ranges' meeting point).
  tsah::TreeSet set(const tsah::FlatBvh& a, const tsah::FlatBvh& b) const {
    tsah::TreeSet s;
    s.ranges = {{animation.startTime(), cut}, {cut, animation.endTime()}};
    s.trees = {a, b};
    return s;
  }
  std::unique_ptr<CpuRuntime> runtime(const tsah::TreeSet& s, LayoutCase c) const {
    CpuRuntime::Config config(2);
    config.layout = c.layout;
    if (c.layout != tsah::Layout::Bvh2) config.isa = c.isa;
    return std::make_unique<CpuRuntime>(s, std::vector<uint32_t>(animation.indices().begin(), animation.indices().end()),
                                        animation.vertexCount(), config);
  }
  float cutFraction() const { return static_cast<float>((cut - open) / (close - open)); }
};

bool sameBits(const Hit& a, const Hit& b) { return std::memcmp(&a, &b, sizeof(Hit)) == 0; }

TEST(MotionBlurTreeSet, StretchesCutTheShutterAtTheSwitch) {
  const SetScene s;
  const std::vector<tsah::TimeRange> ranges = s.set(s.first, s.last).ranges;
  const auto stretches = tsah::shutterStretches(s.animation.times(), s.open, s.close, ranges);
  ASSERT_EQ(stretches.size(), 2u);
  EXPECT_EQ(stretches[0].tree, 0u);
  EXPECT_EQ(stretches[1].tree, 1u);
  EXPECT_EQ(stretches[0].keys, (std::vector<double>{s.open, s.time(2), s.cut}));
  EXPECT_EQ(stretches[1].keys, (std::vector<double>{s.cut, s.time(3), s.close}));
  EXPECT_EQ(stretches[0].fractions.front(), 0.0f);
  EXPECT_EQ(stretches[0].fractions.back(), s.cutFraction());
  EXPECT_EQ(stretches[1].fractions.front(), s.cutFraction());
  EXPECT_EQ(stretches[1].fractions.back(), 1.0f);

  // A cut at a keyframe is that key, once.
  std::vector<tsah::TimeRange> atKey = {{s.animation.startTime(), s.time(2)}, {s.time(2), s.animation.endTime()}};
  const auto keyed = tsah::shutterStretches(s.animation.times(), s.open, s.close, atKey);
  ASSERT_EQ(keyed.size(), 2u);
  EXPECT_EQ(keyed[0].keys, (std::vector<double>{s.open, s.time(2)}));
  EXPECT_EQ(keyed[1].keys, (std::vector<double>{s.time(2), s.time(3), s.close}));

  // No cut inside the shutter: one stretch, the tree of its times; the plain shutter keys.
  const auto before = tsah::shutterStretches(s.animation.times(), s.time(0), s.time(1), ranges);
  ASSERT_EQ(before.size(), 1u);
  EXPECT_EQ(before[0].tree, 0u);
  EXPECT_EQ(before[0].fractions, tsah::motion::keyFractions(before[0].keys));
  const auto after = tsah::shutterStretches(s.animation.times(), s.cut, s.close, ranges);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(after[0].tree, 1u);  // a shutter opening at the switch is the later tree's
  const auto instant = tsah::shutterStretches(s.animation.times(), s.cut, s.cut, ranges);
  ASSERT_EQ(instant.size(), 1u);
  EXPECT_EQ(instant[0].keys, std::vector<double>{s.cut});
  EXPECT_EQ(tsah::shutterStretches(s.animation.times(), s.open, s.close, {})[0].keys,
            tsah::motion::shutterKeys(s.animation.times(), s.open, s.close));
}

// Every ray is traced by the part of its time: hits equal brute force against the triangles at the
// ray's time over the whole shutter (a ray traced by the other part would see the triangles at that
// part's end), and bit for bit those of the set whose two trees are the tree of the ray's part.
TEST(MotionBlurTreeSet, EachRayIsTracedByTheTreeOfItsTime) {
  const SetScene s;
  for (const LayoutCase& c : tsah::test::layoutCases()) {
    SCOPED_TRACE(tsah::test::describe(c));
    auto mixed = s.runtime(s.set(s.first, s.last), c);
    auto onlyFirst = s.runtime(s.set(s.first, s.first), c), onlyLast = s.runtime(s.set(s.last, s.last), c);
    for (CpuRuntime* rt : {mixed.get(), onlyFirst.get(), onlyLast.get()})
      tsah::updateShutter(*rt, s.animation, s.open, s.close);
    ASSERT_EQ(mixed->shutterPartCount(), 2u);
    EXPECT_EQ(mixed->shutterPartTree(0), 0u);
    EXPECT_EQ(mixed->shutterPartTree(1), 1u);
    EXPECT_EQ(mixed->currentTree(), 1u);
    EXPECT_EQ(mixed->shutterKeyCount(), 6u);
    EXPECT_EQ(mixed->keysRefitted(), 6u);  // the cut's positions refitted by both trees
    EXPECT_EQ(mixed->keyTimes(0).back(), s.cutFraction());
    EXPECT_EQ(mixed->keyTimes(1).front(), s.cutFraction());
    EXPECT_EQ(mixed->motionViewAt(0.0f).triIndex, mixed->motionView(0).triIndex);
    EXPECT_EQ(mixed->motionViewAt(s.cutFraction()).triIndex, mixed->motionView(1).triIndex);
    // The parts' key sets are their trees' refits (bvh2: the binary key nodes).
    if (c.layout == tsah::Layout::Bvh2) {
      const auto& part1 = mixed->motionView(1);
      const auto& last1 = onlyLast->motionView(1);
      ASSERT_EQ(part1.nodeCount, last1.nodeCount);
      EXPECT_EQ(std::memcmp(part1.keyNodes, last1.keyNodes, sizeof(tsah::GpuBvhNode) * part1.nodeCount * 3), 0);
    } else if (c.layout == tsah::Layout::Bvh8) {
      ASSERT_EQ(mixed->keyWideNodes8(1, 1).size(), onlyLast->keyWideNodes8(1, 1).size());
      EXPECT_EQ(std::memcmp(mixed->keyWideNodes8(1, 1).data(), onlyLast->keyWideNodes8(1, 1).data(),
                            mixed->keyWideNodes8(1, 1).size_bytes()), 0);
      EXPECT_NE(mixed->keyWideNodes8(1, 0).size(), 0u);
    }

    tsah::test::KeyedGeometry geometry;  // the whole shutter's keys: open, keyframe 2, the cut, keyframe 3, close
    for (uint32_t p = 0; p < 2; ++p)
      for (std::size_t k = p; k < mixed->keyTimes(p).size(); ++k) {
        geometry.fractions.push_back(mixed->keyTimes(p)[k]);
        const float* keyPositions = mixed->motionView(p).keyPositions + k * 3 * std::size_t(s.animation.vertexCount());
        geometry.positions.emplace_back(keyPositions, keyPositions + 3 * std::size_t(s.animation.vertexCount()));
      }
    ASSERT_EQ(geometry.fractions.size(), 5u);
    EXPECT_EQ(geometry.positions[2], s.animation.positionsAt(s.cut));

    const std::vector<Ray> rays = tsah::test::raysAtRuntime(*mixed, 1200, 5);
    std::mt19937 rng(6);
    std::uniform_real_distribution<float> u01(0, 1);
    uint32_t hits = 0, late = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      const float time = i == 0 ? 0.0f : i == 1 ? 1.0f : i == 2 ? s.cutFraction() : u01(rng);
      const Hit got = mixed->closestHit(rays[i], time);
      const Hit ref = tsah::test::bruteForce(*mixed, geometry, time, rays[i]);
      ASSERT_EQ(got.valid(), ref.valid()) << "ray " << i << " time " << time;
      ASSERT_EQ(mixed->anyHit(rays[i], time), ref.valid()) << "ray " << i;
      ASSERT_EQ(mixed->anyHit(rays[i], time, tsah::AnyHitOrder::TreeOrder), ref.valid()) << "ray " << i;
      const CpuRuntime& same = time < s.cutFraction() ? *onlyFirst : *onlyLast;
      ASSERT_TRUE(sameBits(got, same.closestHit(rays[i], time))) << "ray " << i << " time " << time;
      late += time >= s.cutFraction() ? 1 : 0;
      if (!ref.valid()) continue;
      ++hits;
      ASSERT_NEAR(got.t, ref.t, 1e-5f * std::fabs(ref.t)) << "ray " << i;
    }
    EXPECT_GT(hits, rays.size() / 10);
    EXPECT_GT(late, rays.size() / 5);
    EXPECT_LT(late, rays.size() * 4 / 5);
  }
}

// The next frame's shutter (opening where this one closed, past the switch) is one part of the
// later tree and reuses that tree's key at the meeting point; update() returns to the instant.
TEST(MotionBlurTreeSet, APartsKeysAreReusedByTheSameTreeNextFrame) {
  const SetScene s;
  for (const LayoutCase& c : tsah::test::layoutCases()) {
    SCOPED_TRACE(tsah::test::describe(c));
    auto rt = s.runtime(s.set(s.first, s.last), c);
    tsah::updateShutter(*rt, s.animation, s.open, s.close);
    tsah::updateShutter(*rt, s.animation, s.close, s.time(5));
    ASSERT_EQ(rt->shutterPartCount(), 1u);
    EXPECT_EQ(rt->shutterPartTree(0), 1u);
    EXPECT_EQ(rt->keyTimes().size(), 3u);  // close, keyframe 4, keyframe 5
    EXPECT_EQ(rt->keysRefitted(), 2u);
    // Back over the switch: tree 0's part is new (its last frame's part was dropped).
    tsah::updateShutter(*rt, s.animation, s.open, s.close);
    EXPECT_EQ(rt->shutterPartCount(), 2u);
    EXPECT_EQ(rt->keysRefitted(), 5u);  // tree 0's three keys, tree 1's cut and keyframe 3 (close is kept)
    rt->selectTreeAt(s.time(0));
    rt->update(s.animation.positionsAt(s.time(0)));
    EXPECT_FALSE(rt->blurred());
    EXPECT_EQ(rt->shutterPartCount(), 0u);
  }
}

// Parts that break the rules are refused with tsah::ConfigError, a bad coordinate with
// tsah::DataError; the runtime keeps its blurred frame.
TEST(MotionBlurTreeSet, BadPartsAreRefusedAndLeaveTheFrame) {
  const SetScene s;
  auto rt = s.runtime(s.set(s.first, s.last), {});
  tsah::updateShutter(*rt, s.animation, s.open, s.close);
  const std::vector<Ray> rays = tsah::test::raysAtRuntime(*rt, 200, 8);
  std::vector<Hit> before;
  for (const Ray& ray : rays) before.push_back(rt->closestHit(ray, 0.25f));

  const std::vector<float> p0 = s.animation.positionsAt(s.open), p1 = s.animation.positionsAt(s.cut),
                           p2 = s.animation.positionsAt(s.close);
  const std::vector<std::span<const float>> first = {p0, p1}, second = {p1, p2}, one = {p1};
  const float f = s.cutFraction();
  const std::vector<float> t01 = {0.0f, f}, t12 = {f, 1.0f}, t1 = {f}, tGap = {0.9f, 1.0f}, tBack = {f, 0.5f * f};
  using Part = CpuRuntime::ShutterPart;
  const std::vector<std::vector<Part>> bad = {
      {},                                            // no parts
      {{0, t01, first}, {2, t12, second}},           // a tree past the set
      {{1, t01, first}, {1, t12, second}},           // a tree repeated
      {{1, t01, first}, {0, t12, second}},           // trees out of order
      {{0, t01, first}, {1, tGap, second}},          // parts that do not meet
      {{0, t01, first}, {1, t1, one}},               // a part of one key
      {{0, t01, first}, {1, t12, one}},              // key times and position sets differ
      {{0, t01, first}, {1, tBack, second}},         // key times that go back
  };
  for (std::size_t b = 0; b < bad.size(); ++b) {
    SCOPED_TRACE("case " + std::to_string(b));
    EXPECT_THROW(rt->updateShutter(bad[b]), tsah::ConfigError);
    ASSERT_EQ(rt->shutterPartCount(), 2u);
  }
  std::vector<float> nan = p2;
  nan[7] = std::numeric_limits<float>::quiet_NaN();
  const std::vector<std::span<const float>> withNan = {p1, nan};
  const std::vector<Part> badCoordinate = {{0, t01, first}, {1, t12, withNan}};
  EXPECT_THROW(rt->updateShutter(badCoordinate), tsah::DataError);
  ASSERT_EQ(rt->shutterPartCount(), 2u);
  for (std::size_t i = 0; i < rays.size(); ++i) ASSERT_TRUE(sameBits(rt->closestHit(rays[i], 0.25f), before[i]));
}

}  // namespace
