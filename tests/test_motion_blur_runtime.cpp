// Motion blur in the CPU runtime (bvh2): the key refits, boxes that contain their triangles at any
// time, closest / any hits against brute force at each ray's time, the instant cases, the
// pipeline's shutter interval and the errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "anim/generators.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace {

using tsah::Aabb;
using tsah::CpuRuntime;
using tsah::GpuBvhNode;
using tsah::Hit;
using tsah::MotionFrame;
using tsah::Ray;
using tsah::Vec3;

struct Scene {
  anim::Animation animation;
  tsah::FlatBvh tree;
};

Scene makeScene(anim::GeneratorKind kind, uint32_t triangles) {
  Scene s{tsah::test::generatedAnimation(kind, triangles, 6, 5), {}};
  s.tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(s.animation, 0)));
  return s;
}

// A layout and, for the wide ones, the kernels' instruction set.
struct Case {
  tsah::Layout layout = tsah::Layout::Bvh2;
  tsah::SimdIsa isa = tsah::SimdIsa::Sse;
};

// bvh2, and bvh4 / bvh8 with every instruction set this machine runs.
std::vector<Case> cases() {
  std::vector<Case> all{{tsah::Layout::Bvh2, tsah::SimdIsa::Sse}};
  for (tsah::SimdIsa isa : {tsah::SimdIsa::Sse, tsah::SimdIsa::Avx2, tsah::SimdIsa::Avx512}) {
    if (!tsah::isaSupported(isa)) continue;
    all.push_back({tsah::Layout::Bvh4, isa});
    if (isa != tsah::SimdIsa::Sse) all.push_back({tsah::Layout::Bvh8, isa});
  }
  return all;
}

std::string describe(const Case& c) {
  return std::string(tsah::name(c.layout)) + (c.layout == tsah::Layout::Bvh2 ? "" : std::string(" ") + tsah::name(c.isa));
}

std::unique_ptr<CpuRuntime> makeRuntime(const Scene& s, Case c = {}) {
  CpuRuntime::Config config(2);
  config.layout = c.layout;
  if (c.layout != tsah::Layout::Bvh2) config.isa = c.isa;
  return std::make_unique<CpuRuntime>(
      s.tree, std::vector<uint32_t>(s.animation.indices().begin(), s.animation.indices().end()),
      s.animation.vertexCount(), config);
}

double keyframeTime(const anim::Animation& a, uint32_t k) { return a.times()[k]; }

// Rays aimed at the scene as the runtime's positions place it (any layout).
std::vector<Ray> raysFor(const CpuRuntime& rt, uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  tsah::BvhView v;
  v.indices = rt.indices().data();
  v.positions = rt.positions().data();
  return tsah::test::randomRays(v, rt.triangleCount(), rt.bounds(), count, rng);
}

// The triangles of a shutter at a time: the animation's positions at the shutter's keys, lerped.
struct ShutterGeometry {
  std::vector<float> fractions;
  std::vector<std::vector<float>> positions;
  ShutterGeometry(const anim::Animation& a, double open, double close) {
    const std::vector<double> keys = tsah::motion::shutterKeys(a.times(), open, close);
    fractions = tsah::motion::keyFractions(keys);
    for (double t : keys) positions.push_back(a.positionsAt(t));
  }
  Vec3 vertex(uint32_t i, float time) const {
    const tsah::motion::Segment seg = tsah::motion::segmentAt(fractions.data(), int(fractions.size()), time);
    const float* p0 = positions[seg.index].data() + 3 * std::size_t(i);
    const float* p1 = positions[seg.index + 1].data() + 3 * std::size_t(i);
    return tsah::motion::lerpVertex({p0[0], p0[1], p0[2]}, {p1[0], p1[1], p1[2]}, seg.f);
  }
};

// The nearest hit of the triangles lerped at the ray's time (brute force).
Hit bruteForce(const CpuRuntime& rt, const ShutterGeometry& g, float time, const Ray& ray) {
  const tsah::RayPrep prep = tsah::prepareRay(ray);
  Hit best;
  float tmax = ray.tmax;
  const auto idx = rt.indices();
  for (uint32_t tri = 0; tri < rt.triangleCount(); ++tri) {
    float t, u, v;
    if (tsah::intersectWatertight(prep, g.vertex(idx[3 * tri], time), g.vertex(idx[3 * tri + 1], time),
                                  g.vertex(idx[3 * tri + 2], time), ray.tmin, tmax, t, u, v)) {
      best = Hit{t, u, v, tri};
      tmax = t;
    }
  }
  return best;
}

// A blurred scene spanning several keyframes, with the shutter opening and closing between them.
struct Blurred {
  Scene scene = makeScene(anim::GeneratorKind::Swap, 1500);
  double open = 0.5 * (keyframeTime(scene.animation, 1) + keyframeTime(scene.animation, 2));
  double close = 0.3 * keyframeTime(scene.animation, 3) + 0.7 * keyframeTime(scene.animation, 4);
  std::unique_ptr<CpuRuntime> rt;
  explicit Blurred(Case c = {}) : rt(makeRuntime(scene, c)) { tsah::updateShutter(*rt, scene.animation, open, close); }
};

TEST(MotionBlurRuntime, KeysAreTheShutterKeys) {
  Blurred b;
  ASSERT_TRUE(b.rt->blurred());
  EXPECT_EQ(b.rt->keyTimes().size(), 4u);  // open, keyframes 2 and 3, close
  EXPECT_EQ(b.rt->keyTimes().front(), 0.0f);
  EXPECT_EQ(b.rt->keyTimes().back(), 1.0f);
}

// Every node's child box at a random time contains every triangle of the child's subtree lerped
// at that time.
TEST(MotionBlurRuntime, NodeBoxesContainTheirTrianglesAtRandomTimes) {
  Blurred b;
  const tsah::MotionBvhView& view = b.rt->motionView();
  const auto idx = b.rt->indices();
  const auto& tree = b.rt->tree();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u01(0, 1);
  for (int trial = 0; trial < 24; ++trial) {
    const float time = trial == 0 ? 0.0f : (trial == 1 ? 1.0f : u01(rng));
    const MotionFrame frame(view, time);
    // Subtree triangle boxes at this time, children (larger indices) first.
    std::vector<Aabb> subtree(view.nodeCount);
    const auto leafBox = [&](uint32_t first, uint32_t count) {
      Aabb box;
      for (uint32_t s = first; s < first + count; ++s)
        for (int c = 0; c < 3; ++c) box.extend(frame.vertex(idx[3 * std::size_t(tree.triIndex[s]) + c]));
      return box;
    };
    for (uint32_t i = view.nodeCount; i-- > 0;) {
      const GpuBvhNode node = frame.node(int32_t(i));
      for (int c = 0; c < 2; ++c) {
        const int32_t ref = node.childRef(c);
        const Aabb exact = tsah::isLeafRef(ref) ? leafBox(tsah::leafFirstSlot(ref), node.childCount(c))
                                                : subtree[uint32_t(ref)];
        ASSERT_TRUE(node.childBox(c).contains(exact)) << "node " << i << " child " << c << " time " << time;
        subtree[i].extend(exact);
      }
    }
    ASSERT_TRUE(frame.root().contains(subtree[0]));
  }
}

// Closest hit = brute force at the ray's time: the same triangle, or (a tie) another one hit at
// the same t within 1e-5 relative; t within 1e-5 relative. Any hit agrees with closest hit.
TEST(MotionBlurRuntime, ClosestHitMatchesBruteForceAtEachRaysTime) {
  for (const Case& c : cases()) {
  SCOPED_TRACE(describe(c));
  Blurred b(c);
  const ShutterGeometry geometry(b.scene.animation, b.open, b.close);
  const std::vector<Ray> rays = raysFor(*b.rt, 1500, 11);
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> u01(0, 1);
  std::vector<float> times(rays.size());
  for (auto& t : times) t = u01(rng);
  times[0] = 0.0f;
  times[1] = 1.0f;
  const std::vector<Hit> hits = tsah::closestHits(*b.rt, rays, times);
  const std::vector<uint8_t> any = tsah::anyHits(*b.rt, rays, times);
  uint32_t hitCount = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Hit ref = bruteForce(*b.rt, geometry, times[i], rays[i]);
    ASSERT_EQ(hits[i].valid(), ref.valid()) << "ray " << i;
    ASSERT_EQ(any[i] != 0, ref.valid()) << "ray " << i;
    ASSERT_EQ(b.rt->closestHit(rays[i], times[i]).tri, hits[i].tri);
    if (!ref.valid()) continue;
    ++hitCount;
    ASSERT_NEAR(hits[i].t, ref.t, 1e-5f * std::fabs(ref.t)) << "ray " << i;
    if (hits[i].tri != ref.tri) continue;  // a tie at the same t
    EXPECT_EQ(hits[i].u, ref.u);
    EXPECT_EQ(hits[i].v, ref.v);
    ASSERT_EQ(b.rt->anyHit(rays[i], times[i], tsah::AnyHitOrder::TreeOrder), ref.valid());
  }
  EXPECT_GT(hitCount, rays.size() / 10);  // the rays do hit the scene
  }
}

// Blurred results differ from the instant ones: the time is used.
TEST(MotionBlurRuntime, HitsFollowTheRaysTime) {
  Blurred b;
  const std::vector<Ray> rays = raysFor(*b.rt, 600, 21);
  const std::vector<float> open(rays.size(), 0.0f), close(rays.size(), 1.0f);
  const std::vector<Hit> a = tsah::closestHits(*b.rt, rays, open), c = tsah::closestHits(*b.rt, rays, close);
  uint32_t differ = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) differ += a[i].tri != c[i].tri ? 1 : 0;
  EXPECT_GT(differ, 0u);
}

bool sameBits(const Hit& a, const Hit& b) { return std::memcmp(&a, &b, sizeof(Hit)) == 0; }

// A closed shutter (one key) is update(): bit-identical hits at any time.
TEST(MotionBlurRuntime, ClosedShutterIsTheInstant) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 1500);
  const double t = 0.4 * keyframeTime(s.animation, 2) + 0.6 * keyframeTime(s.animation, 3);
  for (const Case& c : cases()) {
  SCOPED_TRACE(describe(c));
  auto instant = makeRuntime(s, c), shutter = makeRuntime(s, c);
  instant->update(s.animation.positionsAt(t));
  const tsah::Shutter closed;  // fraction 0
  const auto [open, close] = tsah::shutterInterval(s.animation, t, 0.1, closed);
  EXPECT_EQ(open, t);
  EXPECT_EQ(close, t);
  tsah::updateShutter(*shutter, s.animation, open, close);
  EXPECT_FALSE(shutter->blurred());
  const std::vector<Ray> rays = raysFor(*instant, 800, 31);
  for (const Ray& ray : rays) {
    const Hit want = instant->closestHit(ray);
    ASSERT_TRUE(sameBits(shutter->closestHit(ray, 0.7f), want));
    ASSERT_TRUE(sameBits(shutter->closestHit(ray), want));
    ASSERT_EQ(shutter->anyHit(ray, 0.3f), instant->anyHit(ray));
  }
  }
}

// A two-key shutter between keyframes: at time 0 and 1 the same hits as the instant runtime at
// those keyframes (the same triangles; t within 1e-5 relative + 1e-6, u and v within 1e-3: the
// instant frame tests with Woop triangles, whose barycentrics carry more rounding, the blurred one
// with the watertight test).
TEST(MotionBlurRuntime, ShutterEndsAreTheKeyframes) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 1500);
  const double t1 = keyframeTime(s.animation, 1), t2 = keyframeTime(s.animation, 2);
  for (const Case& c : cases()) {
  SCOPED_TRACE(describe(c));
  auto blurred = makeRuntime(s, c), instant = makeRuntime(s, c);
  tsah::updateShutter(*blurred, s.animation, t1, t2);
  ASSERT_EQ(blurred->keyTimes().size(), 2u);
  for (const auto& [time, at] : {std::pair{0.0f, t1}, std::pair{1.0f, t2}}) {
    instant->update(s.animation.positionsAt(at));
    const std::vector<Ray> rays = raysFor(*instant, 800, 41);
    uint32_t hits = 0;
    for (const Ray& ray : rays) {
      const Hit want = instant->closestHit(ray), got = blurred->closestHit(ray, time);
      ASSERT_EQ(got.tri, want.tri);
      if (!want.valid()) continue;
      ++hits;
      ASSERT_NEAR(got.t, want.t, 1e-5f * std::fabs(want.t) + 1e-6f);
      ASSERT_NEAR(got.u, want.u, 1e-3f);
      ASSERT_NEAR(got.v, want.v, 1e-3f);
    }
    EXPECT_GT(hits, 0u);
  }
  }
}

TEST(MotionBlurRuntime, UpdateReturnsToTheInstant) {
  Blurred b;
  b.rt->update(b.scene.animation.positionsAt(keyframeTime(b.scene.animation, 2)));
  EXPECT_FALSE(b.rt->blurred());
  EXPECT_TRUE(b.rt->keyTimes().empty());
}

TEST(MotionBlurRuntime, RejectsBadKeys) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 300);
  auto rt = makeRuntime(s);
  const std::vector<float> p = s.animation.positionsAt(0.0), shortSet(p.begin(), p.end() - 3);
  const std::vector<std::span<const float>> two{p, p}, bad{p, shortSet};
  const std::vector<float> good{0.0f, 1.0f}, notFromZero{0.1f, 1.0f}, decreasing{0.0f, 0.0f}, three{0, 0.5f, 1};
  EXPECT_THROW(rt->updateShutter(notFromZero, two), tsah::ConfigError);
  EXPECT_THROW(rt->updateShutter(decreasing, two), tsah::ConfigError);
  EXPECT_THROW(rt->updateShutter(three, two), tsah::ConfigError);
  EXPECT_THROW(rt->updateShutter({}, {}), tsah::ConfigError);
  EXPECT_THROW(rt->updateShutter(good, bad), tsah::DataError);
  EXPECT_FALSE(rt->blurred());
  rt->updateShutter(good, two);
  EXPECT_TRUE(rt->blurred());
  const std::vector<Ray> rays(3);
  const std::vector<float> times(2, 0.5f);
  EXPECT_THROW(tsah::closestHits(*rt, rays, times), tsah::ConfigError);
  EXPECT_THROW(tsah::anyHits(*rt, rays, times), tsah::ConfigError);
}

TEST(MotionBlurPipeline, ShutterIntervalCenteredOpenAndClamped) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 300);
  const anim::Animation& a = s.animation;
  const double start = a.startTime(), end = a.endTime(), mid = 0.5 * (start + end), d = (end - start) / 10;
  tsah::Shutter half{0.5, tsah::Shutter::Mode::Centered};
  auto [o1, c1] = tsah::shutterInterval(a, mid, d, half);
  EXPECT_DOUBLE_EQ(o1, mid - d / 4);
  EXPECT_DOUBLE_EQ(c1, mid + d / 4);
  half.mode = tsah::Shutter::Mode::Open;
  auto [o2, c2] = tsah::shutterInterval(a, mid, d, half);
  EXPECT_DOUBLE_EQ(o2, mid);
  EXPECT_DOUBLE_EQ(c2, mid + d / 2);
  auto [o3, c3] = tsah::shutterInterval(a, end, d, half);  // clamped to the animation
  EXPECT_EQ(o3, end);
  EXPECT_EQ(c3, end);
  half.mode = tsah::Shutter::Mode::Centered;
  auto [o4, c4] = tsah::shutterInterval(a, start, d, half);
  EXPECT_EQ(o4, start);
  EXPECT_DOUBLE_EQ(c4, start + d / 4);
  EXPECT_THROW(tsah::shutterInterval(a, mid, d, tsah::Shutter{1.5}), tsah::ConfigError);
  EXPECT_THROW(tsah::shutterInterval(a, mid, -1.0, half), tsah::ConfigError);
}

}  // namespace
