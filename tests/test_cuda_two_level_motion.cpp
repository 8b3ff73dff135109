// Motion blur of the GPU two-level runtime (GpuTwoLevelRuntime::updateShutter, docs/motion-blur.md
// "Two-level scenes") against the CPU runtime's (TwoLevelRuntime::updateShutter): the same keys and
// key boxes, the same hits (instance, triangle, t) at each ray's time and the brute force over the
// world triangles at that time; the instant frame for a shutter of length zero or in which nothing
// moves; the end of a blurred frame; an instance flattened inside the shutter; bad input. Every test
// skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "tsah/base/error.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"
#include "two_level_motion_reference.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

// Relative tolerance on t against the CPU runtime: both lerp the key matrices, invert them (the
// same code, invertAffineRows, in double) and move the ray into instance space with the same float
// operations without fused multiply-adds, and trace the same lerped triangles; the tolerance only
// leaves room for a compiler's rounding of the transform (as the instant runtime's test). Against
// the brute force in double: the CPU test's 1e-4.
constexpr float kRelativeT = 1e-5f;
constexpr double kBruteForceRelativeT = 1e-4;

tsah::TwoLevelScene loadScene(const fs::path& path) {
  return tsah::loadTwoLevelScene(path.string(), {}, tsah::test::smallTwoLevelOptions());
}

// Rays at their shutter fractions: aimed at the centroid of a random triangle at the ray's time
// (most hit), each followed by the same ray turned around (most miss); every eighth time a key's.
struct TimedRays {
  std::vector<tsah::Ray> rays;
  std::vector<float> times;
};

TimedRays aimedRays(const tsah::TwoLevelScene& scene, std::span<const double> keys, std::span<const float> keyTimes,
                    const tsah::Aabb& bounds, uint32_t pairs, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  TimedRays out;
  for (uint32_t r = 0; r < pairs; ++r) {
    const float tau = r % 8 == 0 ? keyTimes[r / 8 % keyTimes.size()] : unit(rng);
    const tsah::test::WorldAt world = tsah::test::worldTriangles(scene, keys, tau);
    const tsah::Ray ray = tsah::test::rayAtCentroid(scene, world, bounds, rng);
    tsah::Ray back = ray;
    back.dir = tsah::Vec3{0.0f, 0.0f, 0.0f} - ray.dir;
    out.rays.insert(out.rays.end(), {ray, back});
    out.times.insert(out.times.end(), {tau, tau});
  }
  return out;
}

bool sameHit(const tsah::TwoLevelHit& a, const tsah::TwoLevelHit& b) {
  return std::memcmp(&a.t, &b.t, sizeof(float)) == 0 && std::memcmp(&a.u, &b.u, sizeof(float)) == 0 &&
         std::memcmp(&a.v, &b.v, sizeof(float)) == 0 && a.instance == b.instance && a.prim == b.prim;
}

// The GPU runtime blurred over [open, close] against the CPU runtime blurred over the same shutter:
// the keys, the key boxes bit for bit, every ray's closest hit (instance, triangle, t within
// kRelativeT) and any hit (whole ray, and stopping halfway to the hit), and the first `bruteForce`
// aimed rays against the world triangles at their time (a tie: the reported triangle's own distance
// as near, at most 2% of them).
void expectCpuBlurredHits(const tsah::TwoLevelScene& scene, double open, double close, std::size_t expectedKeys,
                          tsah::cuda::GpuTwoLevelRuntime::Config config, uint32_t pairs, uint32_t bruteForce) {
  SCOPED_TRACE("shutter [" + std::to_string(open) + ", " + std::to_string(close) + "] TLAS " +
               tsah::cuda::tlasUpdateName(config.tlas));
  tsah::TwoLevelRuntime cpu(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::cuda::GpuTwoLevelRuntime gpu(scene, config);
  cpu.updateShutter(open, close);
  gpu.updateShutter(open, close);
  ASSERT_TRUE(cpu.blurred());
  ASSERT_TRUE(gpu.blurred());
  ASSERT_EQ(gpu.keyTimes().size(), expectedKeys);
  ASSERT_TRUE(std::equal(gpu.keyTimes().begin(), gpu.keyTimes().end(), cpu.keyTimes().begin(), cpu.keyTimes().end()));
  for (std::size_t k = 0; k < expectedKeys; ++k) {
    const std::vector<tsah::Aabb> boxes = gpu.keyInstanceBoxes(k);
    const std::span<const tsah::Aabb> expected = cpu.keyInstanceBoxes(k);
    ASSERT_EQ(boxes.size(), expected.size());
    EXPECT_EQ(std::memcmp(boxes.data(), expected.data(), boxes.size() * sizeof(tsah::Aabb)), 0) << "key " << k;
  }

  const std::vector<double> keys(cpu.keySceneTimes().begin(), cpu.keySceneTimes().end());
  const TimedRays in = aimedRays(scene, keys, cpu.keyTimes(), tsah::test::unionOf(cpu.keyInstanceBoxes(0)), pairs, 17);
  const std::vector<tsah::TwoLevelHit> got = gpu.closestHits(in.rays, in.times);
  const std::vector<uint8_t> occluded = gpu.anyHits(in.rays, in.times);
  ASSERT_EQ(got.size(), in.rays.size());
  ASSERT_EQ(occluded.size(), in.rays.size());
  std::vector<tsah::Ray> halfway;
  std::vector<float> halfwayTimes;
  std::vector<uint8_t> halfwayExpected;
  uint32_t hits = 0, ties = 0, checked = 0;
  for (std::size_t r = 0; r < in.rays.size(); ++r) {
    const float tau = in.times[r];
    const tsah::TwoLevelHit expected = cpu.closestHit(in.rays[r], tau);
    ASSERT_EQ(got[r].valid(), expected.valid()) << "ray " << r << " tau " << tau;
    EXPECT_EQ(occluded[r] != 0, got[r].valid()) << "ray " << r << " tau " << tau;  // any hit agrees with closest hit
    EXPECT_EQ(occluded[r] != 0, cpu.anyHit(in.rays[r], tau)) << "ray " << r << " tau " << tau;
    if (!expected.valid()) continue;
    ++hits;
    EXPECT_EQ(got[r].instance, expected.instance) << "ray " << r << " tau " << tau;
    EXPECT_EQ(got[r].prim, expected.prim) << "ray " << r << " tau " << tau;
    EXPECT_NEAR(got[r].t, expected.t, kRelativeT * std::max(1.0f, expected.t)) << "ray " << r << " tau " << tau;
    tsah::Ray shorter = in.rays[r];
    shorter.tmax = got[r].t * 0.5f;
    halfway.push_back(shorter);
    halfwayTimes.push_back(tau);
    halfwayExpected.push_back(cpu.anyHit(shorter, tau) ? 1 : 0);
    if (r % 2 == 0 && checked < bruteForce) {  // an aimed ray: the brute force at its time
      ++checked;
      const tsah::test::WorldAt world = tsah::test::worldTriangles(scene, keys, tau);
      const tsah::test::Reference reference = tsah::test::bruteForce(scene, world, in.rays[r]);
      ASSERT_TRUE(reference.valid()) << "ray " << r;
      const double tolerance = kBruteForceRelativeT * std::max(1.0, reference.t);
      EXPECT_NEAR(got[r].t, reference.t, tolerance) << "ray " << r << " tau " << tau;
      if (got[r].instance != reference.instance || got[r].prim != reference.prim) {
        EXPECT_NEAR(tsah::test::triangleT(scene, world, in.rays[r], got[r].instance, got[r].prim), reference.t, tolerance)
            << "ray " << r;
        ++ties;
      }
    }
  }
  EXPECT_GT(hits, in.rays.size() / 4);  // the comparison saw real hits
  EXPECT_LE(ties, checked / 50 + 1) << ties << " ties in " << checked;
  const std::vector<uint8_t> halfwayOccluded = gpu.anyHits(halfway, halfwayTimes);
  for (std::size_t r = 0; r < halfway.size(); ++r)
    EXPECT_EQ(halfwayOccluded[r], halfwayExpected[r]) << "halfway ray " << r;
}

class CudaTwoLevelMotion : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_GPU();
    dir = tsah::test::scratchDir();
    scene = std::make_unique<tsah::TwoLevelScene>(loadScene(tsah::test::writeTwoLevelScene(dir)));
  }
  fs::path dir;
  std::unique_ptr<tsah::TwoLevelScene> scene;
};

// Rotations, non-uniform scales, a mirrored placement, keyed paths, one pose shown by two instances,
// poses of one BLAS at different time offsets, static and animated sources; shutters of 2 and 3
// keys (frames every 0.5), one after two poses' clip ends (one holds its last frame, one moves on),
// and one over the whole scene (25 keys).
TEST_F(CudaTwoLevelMotion, BlurredHitsEqualTheCpuRuntimes) {
  const uint32_t pairs = tsah::test::shortCudaRun() ? 200 : 1000;
  expectCpuBlurredHits(*scene, 2.1, 2.4, 2, {}, pairs, 200);
  expectCpuBlurredHits(*scene, 6.2, 6.9, 3, {}, pairs, 200);
  expectCpuBlurredHits(*scene, 9.2, 9.9, 3, {}, pairs, 100);
  expectCpuBlurredHits(*scene, 0.0, 12.0, 25, {}, pairs, 50);
}

// With a TLAS rebuilt every instant frame, a blurred frame refits the T-SAH TLAS at every key: the
// same hits, and the instant frames after it are the rebuilt ones again.
TEST_F(CudaTwoLevelMotion, ARebuiltTlasConfigurationBlursTheSame) {
  tsah::cuda::GpuTwoLevelRuntime::Config config;
  config.tlas = tsah::cuda::TlasUpdate::Lbvh;
  expectCpuBlurredHits(*scene, 6.2, 6.9, 3, config, 300, 50);
  tsah::cuda::GpuTwoLevelRuntime rebuilt(*scene, config), refit(*scene);
  rebuilt.updateShutter(6.2, 6.9);
  rebuilt.updateAt(7.0);
  refit.updateAt(7.0);
  EXPECT_FALSE(rebuilt.blurred());
  const TimedRays in = aimedRays(*scene, std::vector<double>{7.0}, std::vector<float>{0.0f},
                                       tsah::test::unionOf(refit.downloadInstanceBoxes()), 300, 5);
  const std::vector<tsah::TwoLevelHit> got = rebuilt.closestHits(in.rays), expected = refit.closestHits(in.rays);
  for (std::size_t r = 0; r < in.rays.size(); ++r) EXPECT_TRUE(sameHit(got[r], expected[r])) << "ray " << r;
}

// A shutter of length zero is updateAt(open): not blurred, the instant frame's hits bit for bit
// whatever the rays' times.
TEST_F(CudaTwoLevelMotion, AShutterOfLengthZeroIsTheInstantBitForBit) {
  tsah::cuda::GpuTwoLevelRuntime blurred(*scene), instant(*scene);
  blurred.updateShutter(3.3, 3.3);
  instant.updateAt(3.3);
  EXPECT_FALSE(blurred.blurred());
  EXPECT_TRUE(blurred.keyTimes().empty());
  EXPECT_EQ(blurred.time(), 3.3);
  const TimedRays in = aimedRays(*scene, std::vector<double>{3.3}, std::vector<float>{0.0f},
                                 tsah::test::unionOf(instant.downloadInstanceBoxes()), 500, 3);
  const std::vector<tsah::TwoLevelHit> got = blurred.closestHits(in.rays, in.times), expected = instant.closestHits(in.rays);
  const std::vector<uint8_t> occluded = blurred.anyHits(in.rays, in.times), expectedOccluded = instant.anyHits(in.rays);
  uint32_t hits = 0;
  for (std::size_t r = 0; r < in.rays.size(); ++r) {
    EXPECT_TRUE(sameHit(got[r], expected[r])) << "ray " << r;
    EXPECT_EQ(occluded[r], expectedOccluded[r]) << "ray " << r;
    hits += expected[r].valid() ? 1 : 0;
  }
  EXPECT_GT(hits, in.rays.size() / 4);
}

// Static sources, nothing on a path: a shutter with scene frames inside moves nothing, so it is
// the instant at the open, bit for bit.
TEST(CudaTwoLevelMotionStill, AShutterInWhichNothingMovesIsTheInstantBitForBit) {
  REQUIRE_GPU();
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene scene = loadScene(tsah::test::writeStillScene(dir));
  tsah::cuda::GpuTwoLevelRuntime blurred(scene), instant(scene);
  blurred.updateShutter(0.2, 1.7);  // three frames inside
  instant.updateAt(0.2);
  EXPECT_FALSE(blurred.blurred());
  const TimedRays in = aimedRays(scene, std::vector<double>{0.2}, std::vector<float>{0.0f},
                                 tsah::test::unionOf(instant.downloadInstanceBoxes()), 300, 9);
  const std::vector<tsah::TwoLevelHit> got = blurred.closestHits(in.rays, in.times), expected = instant.closestHits(in.rays);
  uint32_t hits = 0;
  for (std::size_t r = 0; r < in.rays.size(); ++r) {
    EXPECT_TRUE(sameHit(got[r], expected[r])) << "ray " << r;
    hits += expected[r].valid() ? 1 : 0;
  }
  EXPECT_GT(hits, in.rays.size() / 4);
}

// updateAt ends a blurred frame: the instant frame of a fresh runtime, bit for bit; the queries
// without times of a blurred frame see its close.
TEST_F(CudaTwoLevelMotion, UpdateAfterABlurredFrameIsTheInstantAgain) {
  tsah::cuda::GpuTwoLevelRuntime gpu(*scene), fresh(*scene), atClose(*scene);
  gpu.updateShutter(6.2, 6.9);
  ASSERT_TRUE(gpu.blurred());
  atClose.updateAt(6.9);
  const TimedRays in = aimedRays(*scene, std::vector<double>{6.9}, std::vector<float>{0.0f},
                                 tsah::test::unionOf(atClose.downloadInstanceBoxes()), 300, 4);
  std::vector<tsah::TwoLevelHit> got = gpu.closestHits(in.rays), expected = atClose.closestHits(in.rays);
  for (std::size_t r = 0; r < in.rays.size(); ++r) EXPECT_TRUE(sameHit(got[r], expected[r])) << "close, ray " << r;
  gpu.updateAt(4.0);
  fresh.updateAt(4.0);
  EXPECT_FALSE(gpu.blurred());
  got = gpu.closestHits(in.rays, in.times);
  expected = fresh.closestHits(in.rays);
  for (std::size_t r = 0; r < in.rays.size(); ++r) EXPECT_TRUE(sameHit(got[r], expected[r])) << "t 4, ray " << r;
  EXPECT_THROW(gpu.keyInstanceBoxes(0), tsah::ConfigError);
}

// A path scaling x from 1 to -1 over [0, 2] flattens the instance at t = 1 (a key of the shutter):
// no hit there, hits before and after, as the CPU runtime (a moving instance's map is lerped and
// inverted per ray; a singular one is not hit).
TEST(CudaTwoLevelMotionRigid, InstanceFlattenedInsideTheShutterIsNotHitThen) {
  REQUIRE_GPU();
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene scene = loadScene(tsah::test::writeFlattenedTriangleScene(dir));
  tsah::TwoLevelRuntime cpu(scene);
  tsah::cuda::GpuTwoLevelRuntime gpu(scene);
  cpu.updateShutter(0.0, 2.0);
  gpu.updateShutter(0.0, 2.0);
  ASSERT_TRUE(gpu.blurred());
  std::vector<tsah::Ray> rays;
  std::vector<float> times;
  for (int k = 0; k <= 40; ++k) {
    tsah::Ray ray;  // along -z towards (0.1, 0.1, 0): inside the triangle at x-scales > 0.12 or so
    ray.org = {0.1f, 0.1f, 5.0f};
    ray.dir = {0.0f, 0.0f, -1.0f};
    ray.tmin = 0.0f;
    ray.tmax = 100.0f;
    rays.push_back(ray);
    times.push_back(float(k) / 40.0f);
  }
  const std::vector<tsah::TwoLevelHit> got = gpu.closestHits(rays, times);
  const std::vector<uint8_t> occluded = gpu.anyHits(rays, times);
  uint32_t hits = 0;
  for (std::size_t r = 0; r < rays.size(); ++r) {
    const tsah::TwoLevelHit expected = cpu.closestHit(rays[r], times[r]);
    ASSERT_EQ(got[r].valid(), expected.valid()) << "tau " << times[r];
    EXPECT_EQ(occluded[r] != 0, expected.valid()) << "tau " << times[r];
    if (!expected.valid()) continue;
    EXPECT_EQ(got[r].instance, expected.instance) << "tau " << times[r];
    EXPECT_EQ(got[r].prim, expected.prim) << "tau " << times[r];
    EXPECT_NEAR(got[r].t, expected.t, kRelativeT * std::max(1.0f, expected.t)) << "tau " << times[r];
    hits += got[r].valid() ? 1 : 0;
  }
  EXPECT_FALSE(got[20].valid());  // tau 1/2: scene time 1, the flat instant
  EXPECT_GT(hits, 0u);
  EXPECT_LT(hits, rays.size());
}

TEST_F(CudaTwoLevelMotion, BadInputIsRefusedAndLeavesTheFrame) {
  tsah::cuda::GpuTwoLevelRuntime gpu(*scene);
  gpu.updateShutter(6.2, 6.9);
  EXPECT_THROW(gpu.updateShutter(3.0, 2.0), tsah::ConfigError);
  EXPECT_THROW(gpu.updateShutter(std::nan(""), 2.0), tsah::ConfigError);
  EXPECT_THROW(gpu.updateShutter(1.0, std::numeric_limits<double>::infinity()), tsah::ConfigError);
  EXPECT_TRUE(gpu.blurred());  // refused before anything changed
  const std::vector<tsah::Ray> rays(3);
  const std::vector<float> times(2, 0.5f);
  EXPECT_THROW(gpu.closestHits(rays, times), tsah::ConfigError);
  EXPECT_THROW(gpu.anyHits(rays, times), tsah::ConfigError);
  EXPECT_THROW(gpu.keyInstanceBoxes(3), tsah::ConfigError);
  EXPECT_NO_THROW(gpu.keyInstanceBoxes(2));
}

}  // namespace

#endif  // TSAH_HAVE_CUDA
