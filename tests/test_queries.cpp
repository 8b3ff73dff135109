// Closest point within a radius and box overlap on the CPU runtime: equal to brute force over every
// triangle, in every layout, and again after the runtime moves to another frame.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <random>

#include "anim/generators.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/queries.hpp"

namespace {

using tsah::Aabb;
using tsah::Vec3;

struct Frame {
  std::span<const uint32_t> indices;
  std::vector<float> positions;
  Vec3 vertex(uint32_t v) const { return {positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]}; }
  uint32_t triangles() const { return uint32_t(indices.size() / 3); }
};

// Every triangle tested: the nearest within the radius, the lowest id at equal distance.
tsah::PointHit bruteClosest(const Frame& f, Vec3 p, float radius) {
  tsah::PointHit best;
  float best2 = radius * radius;
  for (uint32_t t = 0; t < f.triangles(); ++t) {
    float u, v;
    const Vec3 q = tsah::closestPointOnTriangle(p, f.vertex(f.indices[3 * t]), f.vertex(f.indices[3 * t + 1]),
                                                f.vertex(f.indices[3 * t + 2]), u, v);
    const float d2 = tsah::dot(q - p, q - p);
    if (d2 < best2 || (d2 == best2 && t < best.tri)) best2 = d2, best.tri = t, best.u = u, best.v = v, best.point = q;
  }
  if (best.valid()) best.distance = std::sqrt(best2);
  return best;
}

std::vector<uint32_t> bruteOverlap(const Frame& f, const Aabb& box) {
  std::vector<uint32_t> ids;
  for (uint32_t t = 0; t < f.triangles(); ++t) {
    Aabb b;
    for (int k = 0; k < 3; ++k) b.extend(f.vertex(f.indices[3 * t + k]));
    if (tsah::boxesOverlap(b, box)) ids.push_back(t);
  }
  return ids;
}

struct Scene {
  anim::Animation animation;
  tsah::FlatBvh tree;
  Aabb bounds;
};

Scene makeScene(anim::GeneratorKind kind, uint32_t triangles) {
  Scene s{tsah::test::generatedAnimation(kind, triangles, 6, 3), {}, {}};
  s.tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(s.animation, 0)));
  s.bounds = tsah::test::boxOf(s.animation.bounds());
  return s;
}

std::vector<tsah::Layout> layouts() {
  std::vector<tsah::Layout> all;
  for (tsah::Layout l : {tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8})
    if (tsah::layoutSupported(l)) all.push_back(l);
  return all;
}

std::unique_ptr<tsah::CpuRuntime> runtimeIn(const Scene& s, tsah::Layout layout) {
  tsah::CpuRuntime::Config config(2);
  config.layout = layout;
  return std::make_unique<tsah::CpuRuntime>(
      s.tree, std::vector<uint32_t>(s.animation.indices().begin(), s.animation.indices().end()),
      s.animation.vertexCount(), config);
}

// Random points within (a margin around) the scene's bounds.
std::vector<Vec3> randomPoints(const Aabb& bounds, uint32_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.2f, 1.2f);
  const Vec3 size = bounds.extent();
  std::vector<Vec3> points;
  for (uint32_t i = 0; i < n; ++i)
    points.push_back(bounds.lo + Vec3{u(rng) * size.x, u(rng) * size.y, u(rng) * size.z});
  return points;
}

void expectClosestEqualsBrute(const tsah::CpuRuntime& rt, const Frame& f, const std::vector<Vec3>& points,
                              const std::vector<float>& radii) {
  const std::vector<tsah::PointHit> hits = tsah::closestPoints(rt, points, radii);
  ASSERT_EQ(hits.size(), points.size());
  uint32_t found = 0, missed = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const tsah::PointHit want = bruteClosest(f, points[i], radii[radii.size() == 1 ? 0 : i]);
    const tsah::PointHit& got = hits[i];
    ASSERT_EQ(got.valid(), want.valid()) << "query " << i;
    if (!want.valid()) {
      EXPECT_TRUE(std::isinf(got.distance));
      ++missed;
      continue;
    }
    ++found;
    EXPECT_NEAR(got.distance, want.distance, 1e-5f * std::max(want.distance, 1e-6f)) << "query " << i;
    EXPECT_EQ(got.tri, want.tri) << "query " << i;  // ties resolve to the lowest id in both
    const Vec3 d = got.point - points[i];
    EXPECT_NEAR(std::sqrt(tsah::dot(d, d)), got.distance, 1e-4f * std::max(got.distance, 1e-3f));
    EXPECT_GE(got.u, 0.0f);
    EXPECT_GE(got.v, 0.0f);
    EXPECT_LE(got.u + got.v, 1.0f + 1e-5f);
  }
  // The radii must leave both outcomes in play for the test to mean something.
  if (radii.size() > 1) {
    EXPECT_GT(found, 0u);
    EXPECT_GT(missed, 0u);
  }
}

void expectOverlapEqualsBrute(const tsah::CpuRuntime& rt, const Frame& f, const std::vector<Aabb>& boxes) {
  const tsah::BoxOverlaps got = tsah::overlappingTriangles(rt, boxes);
  ASSERT_EQ(got.offsets.size(), boxes.size() + 1);
  EXPECT_EQ(got.offsets[0], 0u);
  uint64_t total = 0;
  for (std::size_t q = 0; q < boxes.size(); ++q) {
    const std::vector<uint32_t> want = bruteOverlap(f, boxes[q]);
    const std::vector<uint32_t> ids(got.triangles.begin() + got.offsets[q], got.triangles.begin() + got.offsets[q + 1]);
    EXPECT_EQ(ids, want) << "box " << q;
    total += want.size();
  }
  EXPECT_GT(total, 0u);
}

std::vector<Aabb> randomBoxes(const Aabb& bounds, uint32_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> size(0.0f, 0.15f);
  const float diagonal = std::sqrt(tsah::dot(bounds.extent(), bounds.extent()));
  std::vector<Aabb> boxes;
  for (const Vec3& c : randomPoints(bounds, n, seed)) {
    Aabb b;
    const Vec3 half{size(rng) * diagonal, size(rng) * diagonal, size(rng) * diagonal};
    b.lo = c - half;
    b.hi = c + half;
    boxes.push_back(b);
  }
  return boxes;
}

class Queries : public ::testing::TestWithParam<anim::GeneratorKind> {};

TEST_P(Queries, ClosestPointAndOverlapEqualBruteForceInEveryLayoutAndFrame) {
  const Scene s = makeScene(GetParam(), 2000);
  const float diagonal = std::sqrt(tsah::dot(s.bounds.extent(), s.bounds.extent()));
  const std::vector<Vec3> points = randomPoints(s.bounds, 600, 11);
  std::vector<float> radii;  // per point: no limit, and 1 % to 20 % of the diagonal
  std::mt19937 rng(3);
  for (std::size_t i = 0; i < points.size(); ++i)
    radii.push_back(i % 5 == 0 ? INFINITY : diagonal * std::uniform_real_distribution<float>(0.01f, 0.2f)(rng));
  const std::vector<Aabb> boxes = randomBoxes(s.bounds, 200, 17);
  for (tsah::Layout layout : layouts()) {
    SCOPED_TRACE(tsah::name(layout));
    const auto rt = runtimeIn(s, layout);
    // The tree was built over frame 0; the later frames are the animated case (refitted boxes).
    for (double t : s.animation.uniformTimes(3)) {
      SCOPED_TRACE(t);
      Frame f{s.animation.indices(), s.animation.positionsAt(t)};
      rt->update(f.positions);
      expectClosestEqualsBrute(*rt, f, points, radii);
      expectClosestEqualsBrute(*rt, f, points, {INFINITY});
      expectOverlapEqualsBrute(*rt, f, boxes);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Scenes, Queries,
                         ::testing::Values(anim::GeneratorKind::Explode, anim::GeneratorKind::Wave,
                                           anim::GeneratorKind::Swap));

TEST(Queries, PointsOnTheSurfaceAndAtTheRadiusLimit) {
  const Scene s = makeScene(anim::GeneratorKind::Wave, 500);
  const auto rt = runtimeIn(s, tsah::Layout::Bvh2);
  Frame f{s.animation.indices(), s.animation.positionsAt(1.0)};
  rt->update(f.positions);
  // A triangle's centroid: (up to rounding) on the surface, found with a tiny radius.
  const Vec3 c = (f.vertex(f.indices[30]) + f.vertex(f.indices[31]) + f.vertex(f.indices[32])) * (1.0f / 3.0f);
  const tsah::PointHit on = tsah::closestPoints(*rt, std::vector<Vec3>{c}, std::vector<float>{1e-4f})[0];
  ASSERT_TRUE(on.valid());
  EXPECT_LE(on.distance, 1e-5f);
  // Radius just below / at the true distance of a point off the surface.
  const Vec3 off = s.bounds.hi + Vec3{1.0f, 1.0f, 1.0f};
  const tsah::PointHit far = bruteClosest(f, off, INFINITY);
  ASSERT_TRUE(far.valid());
  EXPECT_FALSE(tsah::closestPoints(*rt, std::vector<Vec3>{off}, std::vector<float>{far.distance * 0.99f})[0].valid());
  EXPECT_EQ(tsah::closestPoints(*rt, std::vector<Vec3>{off}, std::vector<float>{far.distance * 1.01f})[0].tri, far.tri);
}

TEST(Queries, BadQueriesAreConfigErrors) {
  const Scene s = makeScene(anim::GeneratorKind::Wave, 200);
  const auto rt = runtimeIn(s, tsah::Layout::Bvh2);
  rt->update(s.animation.positionsAt(0.0));
  const std::vector<Vec3> two{{0, 0, 0}, {1, 1, 1}};
  EXPECT_THROW(tsah::closestPoints(*rt, two, std::vector<float>{1.0f, 1.0f, 1.0f}), tsah::ConfigError);
  EXPECT_THROW(tsah::closestPoints(*rt, two, std::vector<float>{-1.0f}), tsah::ConfigError);
  EXPECT_THROW(tsah::closestPoints(*rt, two, std::vector<float>{NAN}), tsah::ConfigError);
  EXPECT_THROW(tsah::closestPoints(*rt, std::vector<Vec3>{{NAN, 0, 0}}, std::vector<float>{1.0f}), tsah::ConfigError);
  Aabb inverted;
  inverted.lo = {1, 0, 0};
  inverted.hi = {0, 1, 1};
  EXPECT_THROW(tsah::overlappingTriangles(*rt, std::vector<Aabb>{inverted}), tsah::ConfigError);
  // No queries: empty answers.
  EXPECT_TRUE(tsah::closestPoints(*rt, {}, std::vector<float>{1.0f}).empty());
  EXPECT_EQ(tsah::overlappingTriangles(*rt, {}).offsets, std::vector<uint64_t>{0});
}

}  // namespace
