// Motion blur of two-level scenes (docs/motion-blur.md, "Two-level scenes"): the runtime's hits at
// each ray's time against a brute-force test of the world triangles at that time, its key boxes,
// the instant it must equal, and the flat blurred runtime of the baked scene.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "anim/scene.hpp"
#include "anim/tanim.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/image.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_render.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "test_support.hpp"
#include "two_level_motion_reference.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

using tsah::Vec3;

// Relative tolerance on the hit distance: the reference intersects the world triangles in double,
// the runtime the ray moved into instance space in float.
constexpr double kRelativeT = 1e-4;

tsah::TwoLevelScene loadScene(const fs::path& path) {
  return tsah::loadTwoLevelScene(path.string(), {}, tsah::test::smallTwoLevelOptions());
}

// Static sources only (the wave's first frame), moved rigidly: keyed paths with a rotation and a
// scale, a mirrored placement, one instance standing still; 2 fps over [0, 4].
fs::path writeRigidStaticScene(const fs::path& dir) {
  const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 200, 3, 5);
  const std::vector<uint32_t> indices(wave.indices().begin(), wave.indices().end());
  anim::saveTanim(anim::Animation(indices, wave.vertexCount(), wave.positionsAt(wave.startTime()), {0.0}, "ground"),
                  (dir / "ground.tanim").string());
  tsah::test::writeText(dir / "rigid.json", R"({"fps": 2, "time": [0, 4], "objects": [{"file": "ground.tanim", "instances": [
    {"transform": {"translate": [0, -1, 0], "rotate": [10, 20, 30], "scale": [3, 0.5, 2]},
     "path": [{"time": 0}, {"time": 4, "translate": [2, 1, -1], "rotate": [0, 120, 0], "scale": [1, 2, 1]}]},
    {"transform": {"matrix": [-1, 0, 0, 4,  0, 1, 0, 0,  0, 0, 1, 1,  0, 0, 0, 1]},
     "path": [{"time": 0}, {"time": 2, "translate": [0, 3, 0]}, {"time": 4, "rotate": [45, 0, 0]}]},
    {"transform": {"translate": [2, 1, -2]}}]}]})");
  return dir / "rigid.json";
}

// One small triangle moving by +1 along x in its own space over t = 0..1 while its path turns it
// 90 degrees about z: the world position is W(f) p(f), and the lerp of each key's own BLAS box
// moved by that key's matrix misses it at f = 1/2 (docs/motion-blur.md).
fs::path writeTurningSlideScene(const fs::path& dir) {
  const std::vector<float> positions = {0, 0, 0, 0.1f, 0, 0, 0, 0.1f, 0,  1, 0, 0, 1.1f, 0, 0, 1, 0.1f, 0};
  anim::saveTanim(anim::Animation({0, 1, 2}, 3, positions, {0.0, 1.0}, "slide"), (dir / "slide.tanim").string());
  tsah::test::writeText(dir / "turn.json", R"({"fps": 1, "time": [0, 1], "objects": [{"file": "slide.tanim",
    "path": [{"time": 0}, {"time": 1, "rotate": [0, 0, 90]}]}]})");
  return dir / "turn.json";
}

using tsah::test::bruteForce;
using tsah::test::rayAtCentroid;
using tsah::test::Reference;
using tsah::test::triangleT;
using tsah::test::worldTriangles;
using tsah::test::writeStillScene;
using tsah::test::WorldAt;

// Every ray's closest hit (and any hit) at its time against the brute force over the world
// triangles at that time: the same instance and triangle with t within kRelativeT, or a tie (the
// reported triangle's own distance within kRelativeT of the nearest) for at most 2% of the hits.
void expectBruteForceHits(const tsah::TwoLevelScene& scene, tsah::Layout layout, double open, double close,
                          std::size_t expectedKeys, uint32_t rays) {
  SCOPED_TRACE(std::string(tsah::name(layout)) + " shutter [" + std::to_string(open) + ", " + std::to_string(close) + "]");
  tsah::TwoLevelRuntime runtime(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, layout});
  runtime.updateShutter(open, close);
  ASSERT_TRUE(runtime.blurred());
  const std::vector<double> keys = tsah::motion::shutterKeys(scene.frameTimes, open, close);
  ASSERT_EQ(keys.size(), expectedKeys);
  ASSERT_TRUE(std::equal(keys.begin(), keys.end(), runtime.keySceneTimes().begin(), runtime.keySceneTimes().end()));
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  uint32_t hits = 0, ties = 0;
  for (uint32_t r = 0; r < rays; ++r) {
    // Mostly uniform times; every eighth ray at a key exactly.
    const float tau = r % 8 == 0 ? runtime.keyTimes()[r / 8 % keys.size()] : unit(rng);
    const WorldAt world = worldTriangles(scene, keys, tau);
    const tsah::Ray ray = rayAtCentroid(scene, world, tsah::test::unionOf(runtime.keyInstanceBoxes(0)), rng);
    const Reference expected = bruteForce(scene, world, ray);
    const tsah::TwoLevelHit got = runtime.closestHit(ray, tau);
    ASSERT_EQ(got.valid(), expected.valid()) << "ray " << r << " tau " << tau;
    EXPECT_EQ(runtime.anyHit(ray, tau), expected.valid());
    if (!expected.valid()) continue;
    ++hits;
    const double tolerance = kRelativeT * std::max(1.0, expected.t);
    ASSERT_NEAR(got.t, expected.t, tolerance) << "ray " << r << " tau " << tau;
    if (got.instance != expected.instance || got.prim != expected.prim) {
      ASSERT_NEAR(triangleT(scene, world, ray, got.instance, got.prim), expected.t, tolerance) << "ray " << r;
      ++ties;
    }
    // Any hit on a ray stopping halfway: whatever the brute force finds before that.
    tsah::Ray shorter = ray;
    shorter.tmax = float(expected.t * 0.5);
    const Reference nearer = bruteForce(scene, world, shorter);
    EXPECT_EQ(runtime.anyHit(shorter, tau, tsah::AnyHitOrder::TreeOrder), nearer.valid()) << "ray " << r;
  }
  EXPECT_GT(hits, rays / 2);
  EXPECT_LE(ties, hits / 50) << ties << " ties in " << hits << " hits";
}

std::vector<tsah::Layout> cpuLayouts() {
  std::vector<tsah::Layout> layouts{tsah::Layout::Bvh2, tsah::Layout::Bvh4};
  if (tsah::layoutSupported(tsah::Layout::Bvh8)) layouts.push_back(tsah::Layout::Bvh8);
  return layouts;
}

class TwoLevelMotion : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = tsah::test::scratchDir();
    scene = std::make_unique<tsah::TwoLevelScene>(loadScene(tsah::test::writeTwoLevelScene(dir)));
  }
  fs::path dir;
  std::unique_ptr<tsah::TwoLevelScene> scene;
};

// Rotations, non-uniform scales, a mirrored placement, keyed paths, poses of one BLAS at different
// time offsets, static and animated sources; shutters of 2 and 3 keys (frames every 0.5).
TEST_F(TwoLevelMotion, ClosestHitsEqualTheWorldTrianglesAtTheRaysTime) {
  for (const tsah::Layout layout : cpuLayouts()) {
    expectBruteForceHits(*scene, layout, 2.1, 2.4, 2, 250);
    expectBruteForceHits(*scene, layout, 6.2, 6.9, 3, 250);
    expectBruteForceHits(*scene, layout, 9.2, 9.9, 3, 150);  // two poses past their clip's end
  }
}

// Only what moves is blurred: static BLAS never, a pose holding its clip's last frame neither
// (refitted once, instant), a moving pose with the frame's key fractions.
TEST_F(TwoLevelMotion, OnlyMovingPosesAreBlurred) {
  tsah::TwoLevelRuntime runtime(*scene);
  runtime.updateShutter(9.2, 9.9);  // after the wave's last frame (8): offsets 0 hold, 1.5 until 9.5, the loop moves
  ASSERT_TRUE(runtime.blurred());
  EXPECT_FALSE(runtime.blasOf(0).blurred());  // the static ground
  EXPECT_FALSE(runtime.blasOf(3).blurred());  // offset 0: local time 8 at every key
  EXPECT_TRUE(runtime.blasOf(4).blurred());   // offset 1.5: 7.7 .. 8
  EXPECT_TRUE(runtime.blasOf(5).blurred());   // looping
  for (const uint32_t i : {4u, 5u})
    EXPECT_TRUE(std::equal(runtime.keyTimes().begin(), runtime.keyTimes().end(), runtime.blasOf(i).keyTimes().begin(),
                           runtime.blasOf(i).keyTimes().end()));
}

TEST(TwoLevelMotionTurn, TheBoxOfEachKeysOwnBlasBoxWouldMissTheTurningSlide) {
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene scene = loadScene(writeTurningSlideScene(dir));
  tsah::TwoLevelRuntime runtime(scene);
  runtime.updateShutter(0.0, 1.0);
  ASSERT_TRUE(runtime.blurred());
  ASSERT_EQ(runtime.keyTimes().size(), 2u);
  const tsah::CpuRuntime& blas = runtime.blasOf(0);
  ASSERT_TRUE(blas.blurred());
  const tsah::MotionBvhView& view = blas.motionView();
  // Vertex 0 at f = 1/2: p = (0.5, 0, 0), W = lerp(I, Rz(90)), world (0.25, 0.25, 0).
  const float f = 0.5f;
  const tsah::Affine3x4 w = runtime.toWorldAt(0, f);
  const Vec3 p = tsah::motion::lerpVertex({view.keyPositions[0], view.keyPositions[1], view.keyPositions[2]},
                                          {view.keyPositions[9], view.keyPositions[10], view.keyPositions[11]}, f);
  const Vec3 q = w.point(p);
  EXPECT_NEAR(q.x, 0.25f, 1e-6f);
  EXPECT_NEAR(q.y, 0.25f, 1e-6f);
  // Each key's own BLAS box moved by that key's matrix, lerped: x within [-0.05, 0.05] at f = 1/2.
  const anim::SceneSourceInstance& instance = scene.scene.instances[0];
  const tsah::Aabb own0 = tsah::transformBox(view.keyRootBoxes[0], instance.worldAt(0.0));
  const tsah::Aabb own1 = tsah::transformBox(view.keyRootBoxes[1], instance.worldAt(1.0));
  EXPECT_FALSE(tsah::motion::lerpBox(own0, own1, f).contains(tsah::Aabb{q, q}));
  // The runtime's key boxes (of the union over the keys) hold it, and a ray through it hits.
  EXPECT_TRUE(tsah::motion::lerpBox(runtime.keyInstanceBoxes(0)[0], runtime.keyInstanceBoxes(1)[0], f).contains(tsah::Aabb{q, q}));
  tsah::Ray ray;
  ray.org = {0.25f, 0.28f, 1.0f};  // the triangle's centroid at f = 1/2: (0.25, 0.2833)
  ray.dir = {0.0f, 0.0f, -1.0f};
  ray.tmin = 0.0f;
  ray.tmax = 10.0f;
  const tsah::TwoLevelHit hit = runtime.closestHit(ray, f);
  ASSERT_TRUE(hit.valid());
  EXPECT_NEAR(hit.t, 1.0f, 1e-5f);
  EXPECT_FALSE(runtime.closestHit(ray, 0.0f).valid());  // at the open the triangle is elsewhere
  // Along the shutter, a ray down through the triangle's centroid (brute force) at its time hits it.
  const std::vector<double> keys{0.0, 1.0};
  for (int k = 0; k <= 20; ++k) {
    const float tau = float(k) / 20.0f;
    const WorldAt world = worldTriangles(scene, keys, tau);
    const std::vector<double>& p3 = world.positions[0];
    tsah::Ray down = ray;
    down.org = {float((p3[0] + p3[3] + p3[6]) / 3), float((p3[1] + p3[4] + p3[7]) / 3), 1.0f};
    const Reference expected = bruteForce(scene, world, down);
    ASSERT_TRUE(expected.valid());
    const tsah::TwoLevelHit got = runtime.closestHit(down, tau);
    ASSERT_TRUE(got.valid()) << "tau " << tau;
    EXPECT_NEAR(got.t, expected.t, 1e-5) << "tau " << tau;
    EXPECT_TRUE(runtime.anyHit(down, tau));
  }
}

// At random f in every segment, the lerp of an instance's key boxes holds the world position of
// each of its vertices as the runtime computes it (toWorldAt's float matrix times the BLAS's lerped
// vertex, in float), and so does the TLAS's root box.
TEST_F(TwoLevelMotion, KeyBoxesHoldEveryVertexAtEveryTime) {
  for (const auto& [open, close] : {std::pair{2.1, 2.4}, std::pair{6.2, 6.9}, std::pair{0.0, 12.0}}) {
    tsah::TwoLevelRuntime runtime(*scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
    runtime.updateShutter(open, close);
    ASSERT_TRUE(runtime.blurred());
    const std::span<const float> keys = runtime.keyTimes();
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    for (std::size_t s = 0; s + 1 < keys.size(); ++s)
      for (int sample = 0; sample < 6; ++sample) {
        const float f = sample == 0 ? 0.0f : sample == 1 ? 1.0f : sample == 2 ? 1e-7f : unit(rng);
        const float tau = std::min(keys[s + 1], keys[s] + f * (keys[s + 1] - keys[s]));
        const tsah::motion::Segment seg = tsah::motion::segmentAt(keys.data(), int(keys.size()), tau);
        for (uint32_t i = 0; i < scene->instanceCount(); ++i) {
          const tsah::Aabb box = tsah::motion::lerpBox(runtime.keyInstanceBoxes(std::size_t(seg.index))[i],
                                                       runtime.keyInstanceBoxes(std::size_t(seg.index) + 1)[i], seg.f);
          const tsah::Affine3x4 w = runtime.toWorldAt(i, tau);
          const tsah::CpuRuntime& blas = runtime.blasOf(i);
          const tsah::MotionBvhView& view = blas.motionView();
          for (uint32_t v = 0; v < blas.vertexCount(); ++v) {
            Vec3 p{blas.positions()[3 * v], blas.positions()[3 * v + 1], blas.positions()[3 * v + 2]};
            if (blas.blurred()) {
              const float* p0 = view.keyPositions + std::size_t(seg.index) * blas.vertexCount() * 3 + 3 * v;
              const float* p1 = p0 + std::size_t(blas.vertexCount()) * 3;
              p = tsah::motion::lerpVertex({p0[0], p0[1], p0[2]}, {p1[0], p1[1], p1[2]}, seg.f);
            }
            const Vec3 q = w.point(p);
            ASSERT_TRUE(box.contains(tsah::Aabb{q, q})) << "instance " << i << " vertex " << v << " tau " << tau;
          }
        }
      }
  }
}

// instanceKeyBox's pad under rounding: random key maps (rotations, scales with mirrors, translations
// at magnitudes from 1e-3 to 1e6) and points of the local box (often on its sides): the lerp of the
// two keys' boxes holds the lerped map times the lerped vertex, computed in float as the runtime's
// maps are; without the pad (the corners' box, lerped) it does not always.
TEST(TwoLevelMotionBoxes, KeyBoxesHoldTheLerpedMapTimesTheLerpedVertexUnderRounding) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const auto randomMap = [&](double scale) {
    const anim::Matrix4 m = anim::trsMatrix(
        {scale * (20 * unit(rng) - 10), scale * (20 * unit(rng) - 10), scale * (20 * unit(rng) - 10)},
        {360 * unit(rng), 360 * unit(rng), 360 * unit(rng)},
        {(unit(rng) < 0.5 ? -1 : 1) * (0.1 + 3 * unit(rng)), 0.1 + 3 * unit(rng), 0.1 + 3 * unit(rng)});
    tsah::Affine3x4 a;
    for (int i = 0; i < 12; ++i) a.m[i] = float(m[i]);
    return a;
  };
  uint64_t checked = 0, outsideUnpadded = 0;
  for (int c = 0; c < 20000; ++c) {
    const double scale = std::pow(10.0, -3.0 + 9.0 * unit(rng));
    tsah::Aabb local;
    for (int k = 0; k < 2; ++k)
      local.extend(Vec3{float(scale * (2 * unit(rng) - 1)), float(scale * (2 * unit(rng) - 1)), float(scale * (2 * unit(rng) - 1))});
    const tsah::Affine3x4 m0 = randomMap(scale), m1 = unit(rng) < 0.2 ? m0 : randomMap(scale);
    const auto inside = [&] {
      Vec3 p;
      for (int a = 0; a < 3; ++a) {
        const double x = unit(rng);
        p[a] = x < 0.3 ? local.lo[a] : x < 0.6 ? local.hi[a] : float(local.lo[a] + unit(rng) * (local.hi[a] - local.lo[a]));
        p[a] = std::clamp(p[a], local.lo[a], local.hi[a]);
      }
      return p;
    };
    const Vec3 p0 = inside(), p1 = inside();
    const tsah::Aabb b0 = tsah::instanceKeyBox(local, m0), b1 = tsah::instanceKeyBox(local, m1);
    double rows0[12], rows1[12];
    for (int i = 0; i < 12; ++i) {
      rows0[i] = m0.m[i];
      rows1[i] = m1.m[i];
    }
    const tsah::Aabb c0 = tsah::transformBoxRows(local, rows0), c1 = tsah::transformBoxRows(local, rows1);
    for (const float f : {float(unit(rng)), 1e-7f * float(unit(rng)), 1.0f - 6e-8f * float(unit(rng)), 0.5f}) {
      tsah::Affine3x4 m;
      for (int i = 0; i < 12; ++i) m.m[i] = tsah::motion::lerp(m0.m[i], m1.m[i], f);
      const Vec3 q = m.point(tsah::motion::lerpVertex(p0, p1, f));
      ASSERT_TRUE(tsah::motion::lerpBox(b0, b1, f).contains(tsah::Aabb{q, q})) << "case " << c << " f " << f;
      ++checked;
      tsah::Aabb unpadded;
      for (int a = 0; a < 3; ++a) {
        unpadded.lo[a] = tsah::motion::lerp(c0.lo[a], c1.lo[a], f);
        unpadded.hi[a] = tsah::motion::lerp(c0.hi[a], c1.hi[a], f);
      }
      if (!unpadded.contains(tsah::Aabb{q, q})) ++outsideUnpadded;
    }
  }
  EXPECT_GT(outsideUnpadded, 0u) << "of " << checked;
}

TEST_F(TwoLevelMotion, AShutterOfLengthZeroIsTheInstantBitForBit) {
  tsah::TwoLevelRuntime instant(*scene), blurred(*scene);
  instant.update(3.3);
  blurred.updateShutter(3.3, 3.3);
  EXPECT_FALSE(blurred.blurred());
  std::mt19937 rng(5);
  const WorldAt world = worldTriangles(*scene, std::vector<double>{3.3}, 0.0f);
  for (int r = 0; r < 300; ++r) {
    const tsah::Ray ray = rayAtCentroid(*scene, world, tsah::test::unionOf(instant.instanceBoxes()), rng);
    const tsah::TwoLevelHit a = instant.closestHit(ray), b = blurred.closestHit(ray, 0.7f);
    ASSERT_EQ(std::memcmp(&a, &b, sizeof a), 0) << "ray " << r;
    EXPECT_EQ(instant.anyHit(ray), blurred.anyHit(ray, 0.7f));
  }
}

TEST(TwoLevelMotionStill, AShutterInWhichNothingMovesIsTheInstantBitForBit) {
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene scene = loadScene(writeStillScene(dir));
  tsah::TwoLevelRuntime instant(scene), blurred(scene);
  instant.update(0.2);
  blurred.updateShutter(0.2, 1.7);  // three frames inside, nothing moves
  EXPECT_FALSE(blurred.blurred());
  std::mt19937 rng(6);
  const WorldAt world = worldTriangles(scene, std::vector<double>{0.2}, 0.0f);
  for (int r = 0; r < 300; ++r) {
    const tsah::Ray ray = rayAtCentroid(scene, world, tsah::test::unionOf(instant.instanceBoxes()), rng);
    const tsah::TwoLevelHit a = instant.closestHit(ray), b = blurred.closestHit(ray, 0.3f);
    ASSERT_TRUE(a.valid());
    ASSERT_EQ(std::memcmp(&a, &b, sizeof a), 0) << "ray " << r;
  }
}

// Back to the instant: update() after a blurred frame traces as a fresh runtime's update(), bit for
// bit (the poses' blurred runtimes refitted again, the TLAS's boxes the instant's).
TEST_F(TwoLevelMotion, UpdateAfterABlurredFrameIsTheInstantAgain) {
  tsah::TwoLevelRuntime fresh(*scene), used(*scene);
  used.updateShutter(6.2, 6.9);
  ASSERT_TRUE(used.blurred());
  used.update(6.9);
  fresh.update(6.9);
  EXPECT_FALSE(used.blurred());
  for (uint32_t i = 0; i < scene->instanceCount(); ++i) EXPECT_FALSE(used.blasOf(i).blurred());
  std::mt19937 rng(8);
  const WorldAt world = worldTriangles(*scene, std::vector<double>{6.9}, 0.0f);
  for (int r = 0; r < 200; ++r) {
    const tsah::Ray ray = rayAtCentroid(*scene, world, tsah::test::unionOf(fresh.instanceBoxes()), rng);
    const tsah::TwoLevelHit a = fresh.closestHit(ray), b = used.closestHit(ray);
    ASSERT_EQ(std::memcmp(&a, &b, sizeof a), 0) << "ray " << r;
  }
}

TEST_F(TwoLevelMotion, ARebuiltTlasTracesTheSameHits) {
  tsah::TwoLevelRuntime refit(*scene), rebuilt(*scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Rebuild});
  refit.updateShutter(6.2, 6.9);
  rebuilt.updateShutter(6.2, 6.9);
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const std::vector<double> keys(refit.keySceneTimes().begin(), refit.keySceneTimes().end());
  uint32_t hits = 0;
  for (int r = 0; r < 200; ++r) {
    const float tau = unit(rng);
    const tsah::Ray ray = rayAtCentroid(*scene, worldTriangles(*scene, keys, tau), tsah::test::unionOf(refit.keyInstanceBoxes(0)), rng);
    const tsah::TwoLevelHit a = refit.closestHit(ray, tau), b = rebuilt.closestHit(ray, tau);
    ASSERT_EQ(a.valid(), b.valid());
    if (!a.valid()) continue;
    ++hits;
    EXPECT_EQ(a.t, b.t);  // the same BLAS test of the same instance at the same time
  }
  EXPECT_GT(hits, 100u);
}

TEST(TwoLevelMotionRigid, InstanceFlattenedInsideTheShutterIsNotHitThen) {
  const fs::path dir = tsah::test::scratchDir();
  // The path scales x from 1 (t = 0) to -1 (t = 2); frames every 0.5; flat at t = 1.
  const tsah::TwoLevelScene s = loadScene(tsah::test::writeFlattenedTriangleScene(dir));
  tsah::TwoLevelRuntime runtime(s);
  runtime.updateShutter(0.0, 2.0);
  ASSERT_EQ(runtime.keyTimes().size(), 5u);
  tsah::Ray across;  // along x through (x, 1/3, 1/3)
  across.org = {-2.0f, 1.0f / 3.0f, 1.0f / 3.0f};
  across.dir = {1.0f, 0.0f, 0.0f};
  across.tmin = 0.0f;
  across.tmax = 10.0f;
  EXPECT_FALSE(runtime.closestHit(across, 0.5f).valid());  // the key at t = 1: singular
  EXPECT_FALSE(runtime.anyHit(across, 0.5f));
  const tsah::TwoLevelHit open = runtime.closestHit(across, 0.0f);  // (1,0,0) (0,1,0) (0,0,1): x = 1/3
  ASSERT_TRUE(open.valid());
  EXPECT_NEAR(open.t, 2.0f + 1.0f / 3.0f, 1e-5f);
  const tsah::TwoLevelHit close = runtime.closestHit(across, 1.0f);  // mirrored: x = -1/3
  ASSERT_TRUE(close.valid());
  EXPECT_NEAR(close.t, 2.0f - 1.0f / 3.0f, 1e-5f);
}

// Static sources moved rigidly: the blurred two-level frame is the flat bake's blurred frame (the
// bake's keyframes are the scene's frames, so both have the same keys, and lerping W_k p is lerping
// the baked positions): the same triangle (through the bake order) at t within kRelativeT. The
// shutters open and close at scene frames: between frames the bake interpolates its keyframes,
// the two-level scene evaluates the path.
// A rigid static scene as two levels and as its flat bake, with a CPU runtime of the bake's tree.
struct RigidStaticScene {
  tsah::TwoLevelScene scene;
  anim::BakedScene baked;
  tsah::CpuRuntime flat;

  explicit RigidStaticScene(const fs::path& path)
      : scene(loadScene(path)), baked(anim::bakeScene(path.string())), flat(flatRuntime(baked.animation)) {}

  static tsah::CpuRuntime flatRuntime(const anim::Animation& a) {
    const tsah::OptimizedTree tree = tsah::optimizeAnimation(a, tsah::test::smallTwoLevelOptions());
    return tsah::CpuRuntime(tsah::flattenBvh(tree.bvh), std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                            a.vertexCount(), tsah::CpuRuntime::Config(2));
  }
};

TEST(TwoLevelMotionRigid, RigidStaticScenesEqualTheFlatBlurredBake) {
  RigidStaticScene rigid(writeRigidStaticScene(tsah::test::scratchDir()));
  const tsah::TwoLevelScene& scene = rigid.scene;
  const anim::Animation& a = rigid.baked.animation;
  tsah::CpuRuntime& flat = rigid.flat;
  std::vector<uint32_t> firstTriangle;
  uint32_t triangles = 0;
  for (const auto& i : scene.scene.instances) {
    firstTriangle.push_back(triangles);
    triangles += scene.scene.sourceOf(i).triangleCount();
  }
  for (const auto& [open, close] : {std::pair{0.5, 1.0}, std::pair{1.0, 2.5}}) {
    tsah::TwoLevelRuntime runtime(scene);
    runtime.updateShutter(open, close);
    tsah::updateShutter(flat, a, open, close);
    ASSERT_TRUE(runtime.blurred());
    ASSERT_TRUE(std::equal(flat.keyTimes().begin(), flat.keyTimes().end(), runtime.keyTimes().begin(),
                           runtime.keyTimes().end()));
    std::mt19937 rng(13);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const std::vector<double> keys(runtime.keySceneTimes().begin(), runtime.keySceneTimes().end());
    uint32_t hits = 0, ties = 0;
    for (int r = 0; r < 300; ++r) {
      const float tau = unit(rng);
      const tsah::Ray ray = rayAtCentroid(scene, worldTriangles(scene, keys, tau), flat.bounds(), rng);
      const tsah::Hit expected = flat.closestHit(ray, tau);
      const tsah::TwoLevelHit got = runtime.closestHit(ray, tau);
      ASSERT_EQ(got.valid(), expected.valid()) << "ray " << r;
      EXPECT_EQ(runtime.anyHit(ray, tau), flat.anyHit(ray, tau));
      if (!expected.valid()) continue;
      ++hits;
      ASSERT_NEAR(got.t, expected.t, kRelativeT * std::max(1.0f, expected.t)) << "ray " << r;
      if (firstTriangle[got.instance] + got.prim != expected.tri) ++ties;
    }
    EXPECT_GT(hits, 150u);
    EXPECT_LE(ties, hits / 50);
  }
}

TEST_F(TwoLevelMotion, BadShuttersAreRefusedAndLeaveTheFrame) {
  tsah::TwoLevelRuntime runtime(*scene);
  runtime.update(2.0);
  EXPECT_THROW(runtime.updateShutter(3.0, 2.0), tsah::ConfigError);
  EXPECT_THROW(runtime.updateShutter(std::nan(""), 2.0), tsah::ConfigError);
  EXPECT_THROW(runtime.updateShutter(1.0, INFINITY), tsah::ConfigError);
  EXPECT_FALSE(runtime.blurred());
  EXPECT_EQ(runtime.time(), 2.0);
  EXPECT_THROW((void)runtime.keyInstanceBoxes(0), tsah::ConfigError);
  EXPECT_THROW((void)runtime.toWorldAt(scene->instanceCount(), 0.0f), tsah::ConfigError);
}

// The renderer through a blurred two-level frame and through the flat bake's blurred runtime of a
// rigid static scene (the same per-pixel times, the same geometry up to rounding): the same picture
// but for a few pixels near edges; and a blurred frame is not the instant one.
TEST(TwoLevelMotionRender, BlurredFramesLookLikeTheFlatBakesBlurredFrames) {
  RigidStaticScene rigid(writeRigidStaticScene(tsah::test::scratchDir()));
  const tsah::TwoLevelScene& scene = rigid.scene;
  const anim::Animation& a = rigid.baked.animation;
  tsah::CpuRuntime& flat = rigid.flat;
  tsah::TwoLevelRuntime runtime(scene);
  tsah::TwoLevelRenderView view(runtime);
  runtime.updateShutter(1.0, 2.0);
  view.updateMesh();
  tsah::updateShutter(flat, a, 1.0, 2.0);
  const tsah::Camera camera = tsah::fitCamera(flat.bounds());
  const tsah::SceneLighting lighting = tsah::fitLighting(flat.bounds(), camera);
  tsah::RenderSettings settings;
  settings.width = 96;
  settings.height = 72;
  settings.aoSamples = 2;
  settings.shadowSamples = 1;
  tsah::Image twoLevel, flatImage, instant;
  tsah::renderFrame(view, camera, lighting, settings, twoLevel);
  tsah::renderFrame(flat, camera, lighting, settings, flatImage);
  const tsah::ImageDifference d = tsah::compareImages(twoLevel, flatImage);
  EXPECT_LT(d.fractionAbove, 0.01) << "mean " << d.meanAbs << " max " << d.maxAbs;
  runtime.update(2.0);
  view.updateMesh();
  tsah::renderFrame(view, camera, lighting, settings, instant);
  EXPECT_GT(tsah::compareImages(twoLevel, instant).fractionAbove, 0.01);
}

}  // namespace
