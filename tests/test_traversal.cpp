// BVH traversal and the triangle test: closest hit and any hit against brute force on random rays,
// watertightness on shared edges and vertices, agreement of the Woop fast path with the watertight test.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <algorithm>
#include <random>

#include "anim/generators.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/render/sampling.hpp"
#include "tsah/layout/traversal.hpp"
#include "test_support.hpp"

namespace {

using tsah::test::generatedAnimation;

using tsah::Vec3;

tsah::FlatBvh buildTree(const anim::Animation& a, double t, bool binned) {
  const auto pos = a.positionsAt(t);
  std::vector<tsah::Aabb> boxes(a.triangleCount());
  tsah::triangleBoxes(a.indices(), pos, boxes);
  tsah::Bvh bvh;
  if (binned) {
    tsah::BinnedSahBuilder::Config c;
    c.maxLeafSize = 4;
    c.parallelThreshold = 256;  // exercise the parallel top and the stitching
    bvh = tsah::BinnedSahBuilder(c).build(boxes);
  } else {
    bvh = tsah::SweepSahBuilder().build(boxes);
  }
  return tsah::flattenBvh(bvh);
}

// Brute force over every slot with the same triangle test as the traversal.
tsah::Hit bruteForce(const tsah::BvhView& v, uint32_t triangles, const tsah::Ray& ray) {
  tsah::Hit best;
  float tmax = ray.tmax;
  const tsah::RayPrep prep = tsah::prepareRay(ray);
  for (uint32_t s = 0; s < triangles; ++s) {
    const uint32_t* tri = v.indices + 3 * std::size_t(v.triIndex[s]);
    auto fetch = [&](Vec3& a, Vec3& b, Vec3& c) {
      a = v.vertex(tri[0]);
      b = v.vertex(tri[1]);
      c = v.vertex(tri[2]);
    };
    float t, u, w;
    if (tsah::intersectTriangle(ray, prep, v.woop[s], tmax, fetch, t, u, w)) {
      tmax = t;
      best = {t, u, w, v.triIndex[s]};
    }
  }
  return best;
}

Vec3 randomUnit(std::mt19937& rng) {
  std::normal_distribution<float> g;
  Vec3 d{g(rng), g(rng), g(rng)};
  return tsah::normalize(d);
}

void checkAgainstBruteForce(const anim::Animation& a, bool binned, uint32_t rays, uint32_t seed) {
  std::mt19937 rng(seed);
  for (double t : {a.startTime(), 0.5 * (a.startTime() + a.endTime()), a.endTime()}) {
    tsah::CpuRuntime rt(buildTree(a, a.startTime(), binned), {a.indices().begin(), a.indices().end()}, a.vertexCount(),
                        {2});
    rt.update(a.positionsAt(t));  // the tree of frame 0 refitted to frame t
    const tsah::BvhView v = rt.view();
    const tsah::Aabb b = rt.bounds();
    std::uniform_real_distribution<float> ux(b.lo.x, b.hi.x), uy(b.lo.y, b.hi.y), uz(b.lo.z, b.hi.z), u01(0, 1);
    const float diag = std::sqrt(tsah::dot(b.extent(), b.extent()));
    uint32_t hits = 0;
    for (uint32_t i = 0; i < rays; ++i) {
      tsah::Ray ray;
      const uint32_t kind = i % 3;
      if (kind == 0) {  // from outside towards a point of a random triangle (mostly hits)
        const uint32_t* tri = v.indices + 3 * (rng() % rt.triangleCount());
        const Vec3 target = (v.vertex(tri[0]) + v.vertex(tri[1]) + v.vertex(tri[2])) * (1.0f / 3.0f) +
                            randomUnit(rng) * (0.01f * diag);
        ray.org = b.center() + randomUnit(rng) * diag;
        ray.dir = target - ray.org;
      } else {  // from inside in any direction, unnormalized
        ray.org = {ux(rng), uy(rng), uz(rng)};
        ray.dir = randomUnit(rng) * (0.1f + 3.0f * u01(rng));
      }
      ray.tmin = kind == 2 ? 0.01f * u01(rng) : 0.0f;
      ray.tmax = (i % 4 == 0) ? u01(rng) * 2.0f : 3.4e38f;
      const tsah::Hit expect = bruteForce(v, rt.triangleCount(), ray);
      const tsah::Hit got = tsah::closestHit(v, ray);
      ASSERT_EQ(expect.valid(), got.valid()) << "ray " << i << " t=" << t;
      ASSERT_EQ(tsah::anyHit(v, ray), expect.valid()) << "ray " << i;
      if (!expect.valid()) continue;
      ++hits;
      ASSERT_EQ(expect.t, got.t) << "ray " << i;
      if (expect.tri != got.tri) {
        // Two triangles at the same distance (a shared edge): both answers are right.
        continue;
      }
      ASSERT_EQ(expect.u, got.u);
      ASSERT_EQ(expect.v, got.v);
    }
    EXPECT_GT(hits, rays / 10);  // the rays must actually test something
  }
}

TEST(Traversal, MatchesBruteForceOnExplodingSphere) {
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 1500, 8);
  checkAgainstBruteForce(a, true, 2000, 1);
  checkAgainstBruteForce(a, false, 2000, 2);
}

TEST(Traversal, MatchesBruteForceOnWaveAndSwap) {
  checkAgainstBruteForce(generatedAnimation(anim::GeneratorKind::Wave, 1200, 6), true, 2000, 3);
  checkAgainstBruteForce(generatedAnimation(anim::GeneratorKind::Swap, 1200, 6), false, 2000, 4);
}

TEST(Traversal, SingleLeafTreeAndSingleTriangle) {
  // One triangle: the tree is one leaf.
  const anim::Animation a({0, 1, 2}, 3, {0, 0, 0, 1, 0, 0, 0, 1, 0}, {0.0});
  tsah::Bvh bvh;
  bvh.nodes.resize(1);
  bvh.nodes[0].primCount = 1;
  bvh.primIds = {0};
  tsah::refit(bvh, tsah::triangleBoxes(a.indices(), a.keyframe(0), 1));
  tsah::CpuRuntime rt(tsah::flattenBvh(bvh), {0, 1, 2}, 3, {1});
  rt.update(a.keyframe(0));
  tsah::Ray ray{{0.25f, 0.25f, 1.0f}, 0.0f, {0, 0, -1}, 10.0f};
  const tsah::Hit hit = tsah::closestHit(rt.view(), ray);
  ASSERT_TRUE(hit.valid());
  EXPECT_FLOAT_EQ(hit.t, 1.0f);
  EXPECT_FLOAT_EQ(hit.u, 0.25f);
  EXPECT_FLOAT_EQ(hit.v, 0.25f);
  ray.tmax = 0.99f;
  EXPECT_FALSE(tsah::anyHit(rt.view(), ray));
  ray.tmin = 1.01f;
  ray.tmax = 5.0f;
  EXPECT_FALSE(tsah::closestHit(rt.view(), ray).valid());
  ray.org = {0.75f, 0.75f, 1.0f};  // beside the hypotenuse
  ray.tmin = 0.0f;
  EXPECT_FALSE(tsah::anyHit(rt.view(), ray));
}

// A jittered grid sheet: rays aimed exactly at shared edges and vertices must never slip through.
TEST(Traversal, WatertightOnSharedEdgesAndVertices) {
  const uint32_t n = 24;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> jitter(-0.3f, 0.3f), height(-0.2f, 0.2f);
  std::vector<float> pos;
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) {
      const bool border = i == 0 || j == 0 || i == n || j == n;
      pos.push_back(float(i) + (border ? 0.0f : jitter(rng)));
      pos.push_back(height(rng));
      pos.push_back(float(j) + (border ? 0.0f : jitter(rng)));
    }
  std::vector<uint32_t> idx;
  auto v = [&](uint32_t i, uint32_t j) { return j * (n + 1) + i; };
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) {
      idx.insert(idx.end(), {v(i, j), v(i + 1, j), v(i + 1, j + 1)});
      idx.insert(idx.end(), {v(i, j), v(i + 1, j + 1), v(i, j + 1)});
    }
  const anim::Animation a(idx, (n + 1) * (n + 1), pos, {0.0});
  tsah::CpuRuntime rt(buildTree(a, 0.0, true), idx, a.vertexCount(), {2});
  rt.update(pos);
  const tsah::BvhView view = rt.view();

  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  uint32_t tested = 0;
  for (uint32_t t = 0; t < idx.size() / 3; ++t) {
    for (int e = 0; e < 3; ++e) {
      const float* p0 = &pos[3 * idx[3 * t + e]];
      const float* p1 = &pos[3 * idx[3 * t + (e + 1) % 3]];
      // Skip the sheet's outer border, where a ray may legitimately pass.
      const bool onBorder = [&] {
        for (int a2 : {0, 2})
          if ((p0[a2] == 0.0f && p1[a2] == 0.0f) || (p0[a2] == float(n) && p1[a2] == float(n))) return true;
        return false;
      }();
      if (onBorder) continue;
      for (int k = 0; k < 6; ++k) {
        const float s = k == 0 ? 0.0f : u01(rng);  // a vertex, or a point on the edge
        const Vec3 target{p0[0] + s * (p1[0] - p0[0]), p0[1] + s * (p1[1] - p0[1]), p0[2] + s * (p1[2] - p0[2])};
        const bool vertexOnBorder = s == 0.0f && (p0[0] == 0.0f || p0[2] == 0.0f || p0[0] == float(n) || p0[2] == float(n));
        if (vertexOnBorder) continue;
        Vec3 dirUp{u01(rng) - 0.5f, 1.0f + u01(rng), u01(rng) - 0.5f};
        tsah::Ray ray;
        ray.org = target + dirUp * (2.0f + 5.0f * u01(rng));
        ray.dir = target - ray.org;
        ray.tmin = 0.0f;
        ray.tmax = 3.4e38f;
        ++tested;
        ASSERT_TRUE(tsah::closestHit(view, ray).valid()) << "ray through triangle " << t << " edge " << e << " s=" << s;
        ASSERT_TRUE(tsah::anyHit(view, ray));
      }
    }
  }
  EXPECT_GT(tested, 5000u);
}

struct RandomTriangle {
  Vec3 v0, v1, v2;
  tsah::WoopTriangle woop;
};

RandomTriangle randomTriangle(std::mt19937& rng) {
  std::uniform_real_distribution<float> c(-5.0f, 5.0f);
  RandomTriangle t;
  t.v0 = {c(rng), c(rng), c(rng)};
  t.v1 = {c(rng), c(rng), c(rng)};
  t.v2 = {c(rng), c(rng), c(rng)};
  t.woop = tsah::makeWoopTriangle(t.v0, t.v1, t.v2);
  return t;
}

// The combined test (Woop fast path + watertight fallback) and the watertight test alone.
struct BothResults {
  bool combined, watertight, fellBack = false;
  float tc = 0, uc = 0, vc = 0, tw = 0, uw = 0, vw = 0;
};

BothResults testBoth(const RandomTriangle& tri, const tsah::Ray& ray) {
  BothResults r;
  const tsah::RayPrep prep = tsah::prepareRay(ray);
  auto fetch = [&](Vec3& a, Vec3& b, Vec3& c) {
    r.fellBack = true;
    a = tri.v0, b = tri.v1, c = tri.v2;
  };
  r.combined = tsah::intersectTriangle(ray, prep, tri.woop, ray.tmax, fetch, r.tc, r.uc, r.vc);
  r.watertight = tsah::intersectWatertight(prep, tri.v0, tri.v1, tri.v2, ray.tmin, ray.tmax, r.tw, r.uw, r.vw);
  return r;
}

// Well inside well-conditioned triangles the fast path answers alone and agrees with the
// watertight test.
TEST(Traversal, WoopFastPathAgreesWithWatertight) {
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  uint32_t compared = 0, fastOnly = 0;
  for (int i = 0; i < 20000; ++i) {
    const RandomTriangle tri = randomTriangle(rng);
    const Vec3 n = tsah::normalize(tsah::cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
    float b1 = 0.05f + 0.9f * u01(rng), b2 = 0.05f + 0.9f * u01(rng);
    if (b1 + b2 > 0.95f) {
      b1 = 1.0f - b1;
      b2 = 1.0f - b2;
    }
    if (std::min({b1, b2, 1.0f - b1 - b2}) < 0.05f) continue;
    const Vec3 target = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2;
    const Vec3 dir = randomUnit(rng);
    if (std::abs(tsah::dot(dir, n)) < 0.3f) continue;  // grazing: legitimately ill-conditioned
    tsah::Ray ray{target - dir * (1.0f + 10.0f * u01(rng)), 0.0f, dir, 3.4e38f};
    const BothResults r = testBoth(tri, ray);
    ASSERT_TRUE(r.combined) << i;
    ASSERT_TRUE(r.watertight) << i;
    EXPECT_NEAR(r.tc, r.tw, 1e-4f * r.tw) << i;
    EXPECT_NEAR(r.uc, r.uw, 1e-3f) << i;
    EXPECT_NEAR(r.vc, r.vw, 1e-3f) << i;
    EXPECT_NEAR(r.uc, b1, 1e-3f) << i;
    ++compared;
    fastOnly += r.fellBack ? 0 : 1;
  }
  EXPECT_GT(compared, 5000u);
  EXPECT_GT(fastOnly, compared * 99 / 100);  // the fallback is rare away from edges
}

// Rays aimed at points just inside or outside an edge (any conditioning): whenever the fast path
// decides alone, it decides as the watertight test does; so the combined test is watertight.
TEST(Traversal, WoopFastPathClassifiesLikeWatertight) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  uint32_t decidedFast = 0;
  const int cases = 60000;
  for (int i = 0; i < cases; ++i) {
    const RandomTriangle tri = randomTriangle(rng);
    const Vec3 corners[3] = {tri.v0, tri.v1, tri.v2};
    const int e = static_cast<int>(rng() % 3);
    const Vec3 a = corners[e], b = corners[(e + 1) % 3], opposite = corners[(e + 2) % 3];
    const Vec3 onEdge = a + (b - a) * u01(rng);
    const float offset = (u01(rng) < 0.5f ? -1.0f : 1.0f) * std::pow(10.0f, -7.0f + 5.0f * u01(rng));
    const Vec3 target = onEdge + (opposite - onEdge) * offset;
    tsah::Ray ray{target - randomUnit(rng) * (0.5f + 20.0f * u01(rng)), 0.0f, {}, 3.4e38f};
    ray.dir = target - ray.org;
    const BothResults r = testBoth(tri, ray);
    ASSERT_EQ(r.combined, r.watertight) << "case " << i << " offset " << offset << " fell back " << r.fellBack;
    decidedFast += r.fellBack ? 0 : 1;
  }
  EXPECT_GT(decidedFast, uint32_t(cases / 4));  // the check must cover fast-path decisions too
}

// The two-child slab test (SSE on x86) gives bit-identical results to the scalar box test.
TEST(Traversal, ChildBoxTestEqualsScalarBoxTest) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> c(-4.0f, 4.0f), u01(0.0f, 1.0f);
  auto randomBox = [&] {
    tsah::Aabb b;
    b.extend(Vec3{c(rng), c(rng), c(rng)});
    const int flat = static_cast<int>(rng() % 4);  // sometimes flat along one axis
    Vec3 size{u01(rng), u01(rng), u01(rng)};
    if (flat < 3) size[flat] = 0.0f;
    b.extend(b.lo + size);
    return b;
  };
  for (int i = 0; i < 200000; ++i) {
    tsah::GpuBvhNode node{};
    const tsah::Aabb b0 = randomBox(), b1 = randomBox();
    node.setChildBox(0, b0);
    node.setChildBox(1, b1);
    tsah::Ray ray;
    ray.org = {c(rng), c(rng), c(rng)};
    ray.dir = randomUnit(rng);
    if (i % 5 == 0) ray.dir[static_cast<int>(rng() % 3)] = 0.0f;  // axis-parallel components
    if (i % 7 == 0) ray.org = b0.lo;                            // origin on a slab plane
    ray.tmin = i % 3 == 0 ? 0.5f * u01(rng) : 0.0f;
    ray.tmax = i % 2 == 0 ? 10.0f * u01(rng) : 3.4e38f;
    const tsah::RayPrep prep = tsah::prepareRay(ray);
    float s0, s1, v0, v1;
    const bool h0 = tsah::intersectBox(prep, b0, ray.tmin, ray.tmax, s0);
    const bool h1 = tsah::intersectBox(prep, b1, ray.tmin, ray.tmax, s1);
    const int mask = tsah::intersectChildren(tsah::prepareNodeRay(prep), node, ray.tmin, ray.tmax, v0, v1);
    ASSERT_EQ(mask & 1, h0 ? 1 : 0) << i;
    ASSERT_EQ((mask >> 1) & 1, h1 ? 1 : 0) << i;
    if (h0) {
      ASSERT_EQ(0, std::memcmp(&s0, &v0, 4)) << i;
    }
    if (h1) {
      ASSERT_EQ(0, std::memcmp(&s1, &v1, 4)) << i;
    }
  }
}

// The slab set-up replaces a zero or tiny direction component (|d| < 1e-30) by +-1e-30, negative
// only for a negative d (-0 and +0 both become +1e-30), and leaves everything else, NaN included,
// to 1 / d.
TEST(Traversal, SlabSetupClampsTinyDirectionComponents) {
  const float clamped = 1.0f / 1e-30f;
  struct Case {
    float d, inv;
  };
  const Case cases[] = {
      {0.0f, clamped},         {-0.0f, clamped},        {1e-31f, clamped},
      {-1e-31f, -clamped},     {std::numeric_limits<float>::denorm_min(), clamped},
      {-std::numeric_limits<float>::denorm_min(), -clamped},
      {2e-30f, 1.0f / 2e-30f}, {-2e-30f, 1.0f / -2e-30f}, {0.5f, 2.0f}, {-4.0f, -0.25f},
  };
  for (const Case& c : cases) {
    tsah::Ray ray;
    ray.org = {0, 0, 0};
    ray.dir = {c.d, 1.0f, 1.0f};
    EXPECT_EQ(tsah::prepareSlabs(ray).invDir.x, c.inv) << c.d;
  }
  const float nan = std::numeric_limits<float>::quiet_NaN();
  tsah::Ray ray;
  ray.org = {0, 0, 0};
  ray.dir = {nan, -nan, 1.0f};
  const tsah::RayPrep p = tsah::prepareSlabs(ray);
  EXPECT_TRUE(std::isnan(p.invDir.x) && std::isnan(p.invDir.y));
  EXPECT_EQ(p.invDir.z, 1.0f);
}

TEST(Traversal, DegenerateTrianglesAreNeverHit) {
  const Vec3 a{0, 0, 0}, b{1, 1, 1}, c{2, 2, 2};  // collinear
  const tsah::WoopTriangle w = tsah::makeWoopTriangle(a, b, c);
  tsah::Ray ray{{1, 1, 5}, 0.0f, {0, 0, -1}, 100.0f};
  const tsah::RayPrep prep = tsah::prepareRay(ray);
  auto fetch = [&](Vec3& x, Vec3& y, Vec3& z) { x = a, y = b, z = c; };
  float t, u, v;
  EXPECT_FALSE(tsah::intersectTriangle(ray, prep, w, 100.0f, fetch, t, u, v));
  EXPECT_FALSE(tsah::intersectWatertight(prep, a, b, c, 0.0f, 100.0f, t, u, v));
}

}  // namespace
