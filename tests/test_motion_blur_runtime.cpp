// Motion blur in the CPU runtime (bvh2): the key refits, boxes that contain their triangles at any
// time, closest / any hits against brute force at each ray's time, the instant cases, the
// pipeline's shutter interval and the errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "anim/generators.hpp"
#include "shutter_checks.hpp"
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
using tsah::test::expectSameShutter;

struct Scene {
  anim::Animation animation;
  tsah::FlatBvh tree;
};

Scene makeScene(anim::GeneratorKind kind, uint32_t triangles) {
  Scene s{tsah::test::generatedAnimation(kind, triangles, 6, 5), {}};
  s.tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(s.animation, 0)));
  return s;
}

using Case = tsah::test::LayoutCase;
using tsah::test::describe;
std::vector<Case> cases() { return tsah::test::layoutCases(); }

std::unique_ptr<CpuRuntime> makeRuntime(const Scene& s, Case c = {}) {
  CpuRuntime::Config config(2);
  config.layout = c.layout;
  if (c.layout != tsah::Layout::Bvh2) config.isa = c.isa;
  return std::make_unique<CpuRuntime>(
      s.tree, std::vector<uint32_t>(s.animation.indices().begin(), s.animation.indices().end()),
      s.animation.vertexCount(), config);
}

double keyframeTime(const anim::Animation& a, uint32_t k) { return a.times()[k]; }

using tsah::test::raysAtRuntime;

// The triangles of a shutter at a time: the animation's positions at the shutter's keys, lerped.
struct ShutterGeometry : tsah::test::KeyedGeometry {
  ShutterGeometry(const anim::Animation& a, double open, double close) {
    const std::vector<double> keys = tsah::motion::shutterKeys(a.times(), open, close);
    fractions = tsah::motion::keyFractions(keys);
    for (double t : keys) positions.push_back(a.positionsAt(t));
  }
};

using tsah::test::bruteForce;

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
  const std::vector<Ray> rays = raysAtRuntime(*b.rt, 1500, 11);
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
  const std::vector<Ray> rays = raysAtRuntime(*b.rt, 600, 21);
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
  const std::vector<Ray> rays = raysAtRuntime(*instant, 800, 31);
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
    const std::vector<Ray> rays = raysAtRuntime(*instant, 800, 41);
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

// The wide layouts' vertex packets: packet p, lane l at key k holds the three vertices of the
// lane's triangle (the packet's slot) at that key; padding lanes repeat the packet's lane 0.
template <uint32_t N, class VerticesOf>
void expectKeyVertexPackets(const CpuRuntime& rt, const tsah::WideTree<N>& tree, VerticesOf verticesOf) {
  const std::size_t keys = rt.keyTimes().size(), packets = tree.packets().size(), floats = 3 * rt.vertexCount();
  const float* keyPositions = rt.motionView().keyPositions;
  for (std::size_t k = 0; k < keys; ++k) {
    const std::span<const tsah::KeyVertexPacket<N>> keyVertices = verticesOf(k);
    ASSERT_EQ(keyVertices.size(), packets);
    for (std::size_t p = 0; p < packets; ++p)
      for (uint32_t lane = 0; lane < N; ++lane) {
        // A padding lane holds the leaf's first slot, at or before lane 0's.
        const uint32_t* slots = tree.packets()[p].slot;
        const uint32_t tri = tree.triIndex()[slots[lane] < slots[0] ? slots[0] : slots[lane]];
        for (uint32_t j = 0; j < 3; ++j) {
          const float* want = keyPositions + k * floats + 3 * std::size_t(rt.indices()[3 * tri + j]);
          const Vec3 got = keyVertices[p].get(j, lane);
          ASSERT_TRUE(got.x == want[0] && got.y == want[1] && got.z == want[2])
              << "key " << k << " packet " << p << " lane " << lane << " vertex " << j;
        }
      }
  }
}

TEST(MotionBlurRuntime, WideKeyVertexPacketsHoldEverySlotsTriangleAtEachKey) {
  for (const Case& c : cases()) {
    if (c.layout == tsah::Layout::Bvh2) continue;
    SCOPED_TRACE(describe(c));
    Blurred b(c);
    ASSERT_EQ(b.rt->keyTimes().size(), 4u);
    if (c.layout == tsah::Layout::Bvh4)
      expectKeyVertexPackets<4>(*b.rt, *b.rt->wide4(), [&](std::size_t k) { return b.rt->keyVertexPackets4(k); });
    else
      expectKeyVertexPackets<8>(*b.rt, *b.rt->wide8(), [&](std::size_t k) { return b.rt->keyVertexPackets8(k); });
  }
}

// A flat grid of unit squares (two triangles each) at z = 0, and the same grid moved by (1, 0.5, 0)
// at the second key: at time 0.5 every vertex lies at a multiple of 1/4, so rays straight down
// through the vertices and the edge midpoints meet edges exactly (U, V or W zero in float: the
// wide leaf's scalar lanes). Every such ray inside the grid hits (watertight), and every layout
// returns the binary layout's hit bit for bit, or a tie at the same t.
TEST(MotionBlurRuntime, RaysThroughSharedEdgesHitInEveryLayout) {
  constexpr uint32_t G = 12;
  std::vector<uint32_t> indices;
  std::vector<float> key0, key1;
  for (uint32_t j = 0; j <= G; ++j)
    for (uint32_t i = 0; i <= G; ++i) {
      key0.insert(key0.end(), {float(i), float(j), 0.0f});
      key1.insert(key1.end(), {float(i) + 1.0f, float(j) + 0.5f, 0.0f});
    }
  for (uint32_t j = 0; j < G; ++j)
    for (uint32_t i = 0; i < G; ++i) {
      const uint32_t a = j * (G + 1) + i, b = a + 1, c = a + G + 1, d = c + 1;
      indices.insert(indices.end(), {a, b, d, a, d, c});
    }
  std::vector<Aabb> boxes(indices.size() / 3);
  for (std::size_t t = 0; t < boxes.size(); ++t)
    for (int k = 0; k < 3; ++k) boxes[t].extend(Vec3{key0[3 * indices[3 * t + k]], key0[3 * indices[3 * t + k] + 1], 0.0f});
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(boxes));
  const std::vector<float> times{0.0f, 1.0f};
  const std::vector<std::span<const float>> keys{key0, key1};
  std::vector<Ray> rays;
  for (uint32_t j = 2; j <= 4 * G; ++j)  // x, y in [1.5, 12] at time 0.5: inside the moved grid
    for (uint32_t i = 4; i <= 4 * G; ++i) {
      Ray ray;
      ray.org = {0.25f * float(i), 0.25f * float(j), 5.0f};
      ray.dir = {0.0f, 0.0f, -1.0f};
      ray.tmin = 0.0f;
      ray.tmax = 100.0f;
      rays.push_back(ray);
    }
  std::vector<Hit> reference;
  for (const Case& c : cases()) {
    SCOPED_TRACE(describe(c));
    CpuRuntime::Config config(2);
    config.layout = c.layout;
    if (c.layout != tsah::Layout::Bvh2) config.isa = c.isa;
    CpuRuntime rt(tree, indices, (G + 1) * (G + 1), config);
    rt.updateShutter(times, keys);
    for (std::size_t r = 0; r < rays.size(); ++r) {
      const Hit hit = rt.closestHit(rays[r], 0.5f);
      ASSERT_TRUE(hit.valid()) << "ray " << r << " leaks";
      ASSERT_EQ(hit.t, 5.0f);
      ASSERT_TRUE(rt.anyHit(rays[r], 0.5f));
      if (c.layout == tsah::Layout::Bvh2) {
        reference.push_back(hit);
      } else if (hit.tri == reference[r].tri) {
        ASSERT_TRUE(sameBits(hit, reference[r])) << "ray " << r;
      }
    }
  }
}

// Consecutive shutters that meet share their key: it is reused, not refitted, forward and
// backward, and every key set equals a fresh runtime's bit for bit; the same shutter again refits
// nothing.
TEST(MotionBlurRuntime, ConsecutiveShuttersReuseTheSharedKey) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 1500);
  const double t1 = keyframeTime(s.animation, 1), t2 = keyframeTime(s.animation, 2);
  const double a = 0.5 * (t1 + t2), b = t2, c = 0.25 * keyframeTime(s.animation, 3) + 0.75 * t2;
  for (const Case& cs : cases()) {
    SCOPED_TRACE(describe(cs));
    auto rt = makeRuntime(s, cs);
    const auto expectFresh = [&](double open, double close) {
      auto fresh = makeRuntime(s, cs);
      tsah::updateShutter(*fresh, s.animation, open, close);
      EXPECT_EQ(fresh->keysRefitted(), 2u);
      expectSameShutter(*rt, *fresh);
    };
    tsah::updateShutter(*rt, s.animation, a, b);
    EXPECT_EQ(rt->keysRefitted(), 2u);
    tsah::updateShutter(*rt, s.animation, b, c);  // forward: b reused
    EXPECT_EQ(rt->keysRefitted(), 1u);
    expectFresh(b, c);
    tsah::updateShutter(*rt, s.animation, a, b);  // backward: b reused as the last key
    EXPECT_EQ(rt->keysRefitted(), 1u);
    expectFresh(a, b);
    tsah::updateShutter(*rt, s.animation, a, b);  // the same shutter again
    EXPECT_EQ(rt->keysRefitted(), 0u);
    expectFresh(a, b);
    rt->update(s.animation.positionsAt(a));  // back to the instant: nothing is kept
    EXPECT_EQ(rt->keysRefitted(), 0u);
    tsah::updateShutter(*rt, s.animation, a, b);
    EXPECT_EQ(rt->keysRefitted(), 2u);
  }
}

// Two keys of a shutter with the same positions both reuse the one key of the previous shutter
// that has them; the key sets equal a fresh runtime's.
TEST(MotionBlurRuntime, KeysWithTheSamePositionsReuseOneKey) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 1500);
  const std::vector<float> p1 = s.animation.positionsAt(keyframeTime(s.animation, 1));
  const std::vector<float> p2 = s.animation.positionsAt(keyframeTime(s.animation, 2));
  const std::vector<float> times{0.0f, 0.5f, 1.0f};
  const std::vector<std::span<const float>> first{p1, p2, p1}, second{p1, p1, p2};
  for (const Case& c : cases()) {
    SCOPED_TRACE(describe(c));
    auto rt = makeRuntime(s, c), fresh = makeRuntime(s, c);
    rt->updateShutter(times, first);
    EXPECT_EQ(rt->keysRefitted(), 3u);
    rt->updateShutter(times, second);
    EXPECT_EQ(rt->keysRefitted(), 0u);
    fresh->updateShutter(times, second);
    expectSameShutter(*rt, *fresh);
  }
}

// While blurred the untimed queries trace at time 1 (the instant triangles are not kept), and
// positions() and bounds() are the last key's.
TEST(MotionBlurRuntime, UntimedQueriesTraceTheLastKeyWhileBlurred) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(describe(c));
    Blurred b(c);
    const std::size_t keys = b.rt->keyTimes().size(), floats = 3 * std::size_t(b.rt->vertexCount());
    const tsah::MotionBvhView& view = b.rt->motionView();
    EXPECT_EQ(std::memcmp(b.rt->positions().data(), view.keyPositions + (keys - 1) * floats, floats * sizeof(float)), 0);
    const Aabb bounds = b.rt->bounds();
    EXPECT_EQ(std::memcmp(&bounds, &view.keyRootBoxes[keys - 1], sizeof(Aabb)), 0);
    uint32_t hits = 0;
    for (const Ray& ray : raysAtRuntime(*b.rt, 600, 61)) {
      const Hit atClose = b.rt->closestHit(ray, 1.0f);
      ASSERT_TRUE(sameBits(b.rt->closestHit(ray), atClose));
      ASSERT_EQ(b.rt->anyHit(ray), atClose.valid());
      hits += atClose.valid() ? 1 : 0;
    }
    EXPECT_GT(hits, 0u);
  }
}

// A bad coordinate in a later key is refused before any key is refitted: the runtime keeps its
// shutter and its own frame (the instant hits), in every layout.
TEST(MotionBlurRuntime, ABadKeyLeavesTheRuntimeAsItWas) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 1500);
  const double t1 = keyframeTime(s.animation, 1), t2 = keyframeTime(s.animation, 2), t3 = keyframeTime(s.animation, 3);
  const std::vector<float> p1 = s.animation.positionsAt(t1), p2 = s.animation.positionsAt(t2);
  const std::vector<float> p3 = s.animation.positionsAt(t3);
  std::vector<float> bad = p3;
  bad[7] = std::nanf("");
  const std::vector<float> times{0.0f, 0.5f, 1.0f};
  const std::vector<std::span<const float>> good{p1, p2, p1}, badKeys{p3, bad, p1};  // p3 new, before the bad key
  for (const Case& c : cases()) {
    SCOPED_TRACE(describe(c));
    auto rt = makeRuntime(s, c);
    rt->updateShutter(times, good);
    const std::vector<Ray> rays = raysAtRuntime(*rt, 400, 51);
    std::vector<Hit> instant, blurred;
    for (const Ray& ray : rays) instant.push_back(rt->closestHit(ray)), blurred.push_back(rt->closestHit(ray, 0.25f));
    EXPECT_THROW(rt->updateShutter(times, badKeys), tsah::DataError);
    ASSERT_EQ(rt->keyTimes().size(), 3u);
    for (std::size_t r = 0; r < rays.size(); ++r) {
      ASSERT_TRUE(sameBits(rt->closestHit(rays[r]), instant[r])) << "ray " << r;
      ASSERT_TRUE(sameBits(rt->closestHit(rays[r], 0.25f), blurred[r])) << "ray " << r;
    }
  }
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
