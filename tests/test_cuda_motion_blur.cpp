// Motion blur on the CUDA runtime: updateShutter refits the tree at every key of a shutter, and
// each key's boxes and positions equal the CPU runtime's update at that key's positions bit for bit
// (the same refit from the same positions); an update or rebuild ends the blurred frame; bad keys
// and the compressed layout are refused. Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "anim/generators.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/woop.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

namespace tc = tsah::cuda;
using tsah::test::generatedAnimation;

tsah::FlatBvh sahTree(const anim::Animation& a, uint32_t maxLeaf) {
  tsah::Bvh bvh = tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0));
  tsah::LeafCollapser::Config c;
  c.maxLeafSize = maxLeaf;
  return tsah::flattenBvh(maxLeaf > 1 ? tsah::LeafCollapser(c).collapse(bvh) : bvh);
}

tsah::CpuRuntime cpuRuntime(const tsah::FlatBvh& tree, const anim::Animation& a) {
  return tsah::CpuRuntime(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
}

// A shutter's keys as the design makes them: open, every keyframe strictly inside, close; with the
// positions of the animation at each key and the keys' shutter fractions.
struct ShutterKeys {
  std::vector<float> fractions;
  std::vector<std::vector<float>> positions;
  std::vector<std::span<const float>> spans() const { return {positions.begin(), positions.end()}; }
};

ShutterKeys shutterKeys(const anim::Animation& a, double open, double close) {
  const std::vector<double> times = tsah::motion::shutterKeys(a.times(), open, close);
  ShutterKeys keys;
  keys.fractions = tsah::motion::keyFractions(times);
  for (double t : times) keys.positions.push_back(a.positionsAt(t));
  return keys;
}

void expectSameTree(const tsah::FlatBvh& got, const tsah::FlatBvh& expect, const std::string& what) {
  ASSERT_EQ(got.interiorCount, expect.interiorCount) << what;
  ASSERT_EQ(got.triIndex, expect.triIndex) << what;
  ASSERT_EQ(0, std::memcmp(&got.rootBoxes[0], &expect.rootBoxes[0], sizeof(tsah::Aabb))) << "root, " << what;
  for (uint32_t i = 0; i < expect.interiorCount; ++i)
    ASSERT_EQ(0, std::memcmp(&got.nodes[i], &expect.nodes[i], sizeof(tsah::GpuBvhNode))) << "node " << i << ", " << what;
  EXPECT_FALSE(tsah::validateFlatBvh(got).has_value()) << what;
}

// Every key of shutters over one, several and no keyframes inside, for single-triangle and
// collapsed leaves, with and without graphs: boxes and positions equal CpuRuntime::update's.
TEST(CudaMotionBlur, EveryKeyEqualsTheCpuUpdateAtItsPositionsExactly) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 4000, 6);
  const double t0 = a.startTime(), span = a.endTime() - a.startTime();
  for (uint32_t maxLeaf : {1u, 8u}) {
    const tsah::FlatBvh tree = sahTree(a, maxLeaf);
    tsah::CpuRuntime cpu = cpuRuntime(tree, a);
    tc::GpuRuntime gpu(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, maxLeaf == 1));
    for (auto [open, close] : {std::pair{t0 + 0.05 * span, t0 + 0.1 * span}, std::pair{t0 + 0.1 * span, t0 + 0.9 * span},
                               std::pair{t0, t0 + span}}) {
      const ShutterKeys keys = shutterKeys(a, open, close);
      ASSERT_GE(keys.fractions.size(), 2u);
      const tc::UpdateTimings timings = gpu.updateShutter(keys.fractions, keys.spans());
      EXPECT_GE(timings.totalMs(), 0.0);
      ASSERT_TRUE(gpu.blurred());
      ASSERT_EQ(gpu.shutterKeyCount(), keys.fractions.size());
      for (uint32_t k = 0; k < keys.fractions.size(); ++k) {
        const std::string what = "leaf " + std::to_string(maxLeaf) + ", shutter [" + std::to_string(open) + ", " +
                                 std::to_string(close) + "], key " + std::to_string(k);
        cpu.update(keys.positions[k]);
        const std::vector<float> pos = gpu.downloadKeyPositions(k);
        ASSERT_EQ(pos.size(), keys.positions[k].size());
        ASSERT_EQ(0, std::memcmp(pos.data(), keys.positions[k].data(), pos.size() * sizeof(float))) << what;
        expectSameTree(gpu.downloadKeyTree(k), cpu.tree(), what);
      }
      // Tracing without times sees the last key (the CPU runtime was last updated to it).
      expectSameTree(gpu.downloadTree(), cpu.tree(), "the current tree after updateShutter");
      EXPECT_THROW(gpu.downloadKeyTree(uint32_t(keys.fractions.size())), tsah::ConfigError);
    }
  }
}

// updateShutterAt interpolates and refits every key on the device: each key equals the CPU update
// at the animation's positions of that key time, and updateShutter from those host positions.
TEST(CudaMotionBlur, ShutterAtKeyframesEqualsTheCpuUpdateAtEveryKey) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 3000, 7, 5);
  const double t0 = a.startTime(), span = a.endTime() - a.startTime();
  const tsah::FlatBvh tree = sahTree(a, 8);
  tsah::CpuRuntime cpu = cpuRuntime(tree, a);
  for (bool graphs : {true, false}) {
    tc::GpuRuntime gpu(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
    tc::GpuRuntime fromHost(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
    // Inside one keyframe interval, over several, starting on a keyframe, the whole animation.
    for (auto [open, close] : {std::pair{t0 + 0.02 * span, t0 + 0.07 * span}, std::pair{t0 + 0.3 * span, t0 + 0.8 * span},
                               std::pair{a.times()[2], a.times()[4] + 0.01 * span}, std::pair{t0, t0 + span}}) {
      const ShutterKeys keys = shutterKeys(a, open, close);
      gpu.updateShutterAt(open, close);
      fromHost.updateShutter(keys.fractions, keys.spans());
      ASSERT_TRUE(gpu.blurred());
      ASSERT_EQ(gpu.shutterKeyCount(), keys.fractions.size()) << "keys of [" << open << ", " << close << "]";
      for (uint32_t k = 0; k < keys.fractions.size(); ++k) {
        const std::string what = "graphs " + std::to_string(graphs) + ", shutter [" + std::to_string(open) + ", " +
                                 std::to_string(close) + "], key " + std::to_string(k);
        cpu.update(keys.positions[k]);
        const std::vector<float> pos = gpu.downloadKeyPositions(k);
        ASSERT_EQ(0, std::memcmp(pos.data(), keys.positions[k].data(), pos.size() * sizeof(float))) << what;
        const tsah::FlatBvh got = gpu.downloadKeyTree(k);
        expectSameTree(got, cpu.tree(), what);
        expectSameTree(fromHost.downloadKeyTree(k), got, "host positions, " + what);
      }
    }
    // A closed shutter is the instant: not blurred, the tree of updateAt.
    const double t = t0 + 0.41 * span;
    gpu.updateShutterAt(t, t);
    EXPECT_FALSE(gpu.blurred());
    cpu.update(a.positionsAt(t));
    expectSameTree(gpu.downloadTree(), cpu.tree(), "closed shutter");
    EXPECT_THROW(gpu.updateShutterAt(t, t - 0.1), tsah::ConfigError);
    EXPECT_THROW(gpu.updateShutterAt(std::nan(""), t), tsah::ConfigError);
  }
}

// The geometry at shutter fraction tau, on the host: the oracle of the device's lerp.
std::vector<float> positionsAtFraction(const ShutterKeys& keys, float tau) {
  const tsah::motion::Segment seg = tsah::motion::segmentAt(keys.fractions.data(), int(keys.fractions.size()), tau);
  const std::vector<float>&a = keys.positions[seg.index], &b = keys.positions[seg.index + 1];
  std::vector<float> p(a.size());
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = tsah::motion::lerp(a[i], b[i], seg.f);
  return p;
}

// Closest hit over every triangle with the watertight test.
tsah::Hit bruteForce(const anim::Animation& a, const std::vector<float>& p, const tsah::Ray& ray) {
  const tsah::RayPrep prep = tsah::prepareRay(ray);
  const auto idx = a.indices();
  const auto vertex = [&](uint32_t v) { return tsah::Vec3{p[3 * v], p[3 * v + 1], p[3 * v + 2]}; };
  tsah::Hit best;
  float tmax = ray.tmax;
  for (uint32_t tri = 0; tri < a.triangleCount(); ++tri) {
    float t, u, v;
    if (tsah::intersectWatertight(prep, vertex(idx[3 * tri]), vertex(idx[3 * tri + 1]), vertex(idx[3 * tri + 2]),
                                  ray.tmin, tmax, t, u, v)) {
      tmax = t;
      best = tsah::Hit{t, u, v, tri};
    }
  }
  return best;
}

// Rays towards triangles of the key-0 frame and from inside the bounds, at random shutter fractions
// (and exactly 0, 1 and each key's fraction).
struct TimedRays {
  std::vector<tsah::Ray> rays;
  std::vector<float> times;
};

TimedRays timedRays(const anim::Animation& a, const ShutterKeys& keys, uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::normal_distribution<float> g;
  const std::vector<float>& p = keys.positions[0];
  tsah::Aabb b;
  for (std::size_t i = 0; i < p.size(); i += 3) b.extend(tsah::Vec3{p[i], p[i + 1], p[i + 2]});
  const float diag = std::sqrt(tsah::dot(b.extent(), b.extent()));
  const auto unit = [&] { return tsah::normalize(tsah::Vec3{g(rng), g(rng), g(rng)}); };
  TimedRays out;
  const auto idx = a.indices();
  for (uint32_t i = 0; i < count; ++i) {
    tsah::Ray ray;
    if (i % 3 != 2) {
      const uint32_t* tri = idx.data() + 3 * (rng() % a.triangleCount());
      tsah::Vec3 target = b.center();
      for (int c = 0; c < 3; ++c) target = target + (tsah::Vec3{p[3 * tri[c]], p[3 * tri[c] + 1], p[3 * tri[c] + 2]} - b.center()) * (1.0f / 3.0f);
      ray.org = b.center() + unit() * diag;
      ray.dir = target - ray.org;
    } else {
      const tsah::Vec3 e = b.extent();
      ray.org = b.lo + tsah::Vec3{e.x * u01(rng), e.y * u01(rng), e.z * u01(rng)};
      ray.dir = unit();
    }
    ray.tmin = 0.0f;
    ray.tmax = i % 4 == 0 ? 2.0f * u01(rng) : 3.4e38f;
    out.rays.push_back(ray);
    const uint32_t pick = i % 8;
    out.times.push_back(pick < keys.fractions.size() ? keys.fractions[pick] : u01(rng));
  }
  return out;
}

// Closest and any hits of a blurred frame equal the CPU runtime's blurred frame (updateShutter with
// the same keys) and a brute force over the geometry at each ray's time,
// lerped and tested with the same float operations (no fused multiply-adds on either side): the
// same answer to "is there a hit", the same distance bit for bit, the same triangle and weights
// unless two triangles lie at that distance.
TEST(CudaMotionBlur, BlurredHitsEqualABruteForceAtEachRaysTime) {
  REQUIRE_GPU();
  // Every vertex moving, and a still wave beside a moving part (the layout's records alike at every
  // key: one key read, no lerp).
  for (int scene = 0; scene < 3; ++scene) {
    const auto a = scene == 2 ? tsah::test::mostlyStaticAnimation(500, 200)
                              : generatedAnimation(scene == 0 ? anim::GeneratorKind::Explode : anim::GeneratorKind::Wave,
                                                   600, 6, 3);
    const double t0 = a.startTime(), span = a.endTime() - a.startTime();
    for (uint32_t maxLeaf : {1u, 4u}) {
      const tsah::FlatBvh tree = sahTree(a, maxLeaf);
      tc::GpuRuntime gpu(tree, a);
      tsah::CpuRuntime cpu = cpuRuntime(tree, a);
      const double open = t0 + 0.1 * span, close = t0 + 0.85 * span;
      const ShutterKeys keys = shutterKeys(a, open, close);
      gpu.updateShutterAt(open, close);
      cpu.updateShutter(keys.fractions, keys.spans());
      ASSERT_TRUE(gpu.blurred());
      ASSERT_TRUE(cpu.blurred());
      const TimedRays r = timedRays(a, keys, 4000, 17 + maxLeaf);
      tsah::RayPassStats stats;
      const std::vector<tsah::Hit> got = gpu.closestHits(r.rays, r.times, &stats);
      const std::vector<uint8_t> occluded = gpu.anyHits(r.rays, r.times);
      EXPECT_EQ(stats.rays, r.rays.size());
      uint32_t hits = 0, ties = 0;
      for (std::size_t i = 0; i < r.rays.size(); ++i) {
        const tsah::Hit expect = bruteForce(a, positionsAtFraction(keys, r.times[i]), r.rays[i]);
        ASSERT_EQ(got[i].valid() ? 1 : 0, occluded[i]) << "any hit against closest hit, ray " << i;
        // The CPU runtime's blurred frame: the same hit (its traversal order may pick the other
        // triangle of a tie), and the same any-hit answer.
        const tsah::Hit onCpu = cpu.closestHit(r.rays[i], r.times[i]);
        ASSERT_EQ(onCpu.valid(), got[i].valid()) << "CPU runtime, ray " << i;
        ASSERT_EQ(cpu.anyHit(r.rays[i], r.times[i]) ? 1 : 0, occluded[i]) << "CPU runtime any hit, ray " << i;
        if (onCpu.valid()) {
          ASSERT_EQ(onCpu.t, got[i].t) << "CPU runtime, ray " << i;
        }
        ASSERT_EQ(expect.valid(), got[i].valid()) << "ray " << i << " at " << r.times[i];
        if (!expect.valid()) continue;
        ++hits;
        ASSERT_EQ(expect.t, got[i].t) << "ray " << i << " at " << r.times[i];
        if (expect.tri != got[i].tri) {
          ++ties;
          continue;
        }
        ASSERT_EQ(expect.u, got[i].u) << "ray " << i;
        ASSERT_EQ(expect.v, got[i].v) << "ray " << i;
      }
      EXPECT_GT(hits, r.rays.size() / 4) << "the rays must actually hit something";
      EXPECT_LE(ties, r.rays.size() / 100);
      EXPECT_THROW(gpu.closestHits(r.rays, std::span(r.times).first(10)), tsah::ConfigError);
    }
  }
}

// A closed shutter (shutter 0) is today's path: hits with times are the hits without, bit for bit.
TEST(CudaMotionBlur, ClosedShutterHitsAreTheInstantsBitForBit) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 2000, 5, 9);
  tc::GpuRuntime gpu(sahTree(a, 4), a);
  const double t = 0.5 * (a.startTime() + a.endTime());
  gpu.updateShutterAt(t, t);
  ASSERT_FALSE(gpu.blurred());
  const ShutterKeys keys = shutterKeys(a, t, t + 1e-3);
  const TimedRays r = timedRays(a, keys, 3000, 4);
  const std::vector<tsah::Hit> timed = gpu.closestHits(r.rays, r.times), plain = gpu.closestHits(r.rays);
  ASSERT_EQ(0, std::memcmp(timed.data(), plain.data(), plain.size() * sizeof(tsah::Hit)));
  EXPECT_EQ(gpu.anyHits(r.rays, r.times), gpu.anyHits(r.rays));
}

TEST(CudaMotionBlur, AnUpdateOrRebuildEndsTheBlurredFrame) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 1500, 4);
  const tsah::FlatBvh tree = sahTree(a, 4);
  tc::GpuRuntime gpu(tree, a);
  EXPECT_FALSE(gpu.blurred());
  EXPECT_THROW(gpu.downloadKeyTree(0), tsah::ConfigError);
  const ShutterKeys keys = shutterKeys(a, a.startTime(), a.endTime());
  const auto blur = [&] {
    gpu.updateShutter(keys.fractions, keys.spans());
    ASSERT_TRUE(gpu.blurred());
  };
  blur();
  gpu.updateAt(a.startTime());
  EXPECT_FALSE(gpu.blurred());
  EXPECT_EQ(gpu.shutterKeyCount(), 0u);
  EXPECT_THROW(gpu.downloadKeyPositions(0), tsah::ConfigError);
  blur();
  gpu.update(keys.positions[0]);
  EXPECT_FALSE(gpu.blurred());
  blur();
  gpu.rebuildAt(a.startTime());
  EXPECT_FALSE(gpu.blurred());
  // One key is update(): not blurred, the tree refitted to that key.
  tsah::CpuRuntime cpu = cpuRuntime(tree, a);
  const std::vector<float> mid = a.positionsAt(0.5 * (a.startTime() + a.endTime()));
  const std::vector<std::span<const float>> one{mid};
  gpu.updateShutter(std::vector<float>{0.0f}, one);
  cpu.update(mid);
  EXPECT_FALSE(gpu.blurred());
  expectSameTree(gpu.downloadTree(), cpu.tree(), "one key");
}

// Bad key times are the caller's mistake (ConfigError), a wrong coordinate count is bad data
// (DataError); both are refused before anything is refitted, so the blurred frame stays.
TEST(CudaMotionBlur, BadKeysAreRefusedAndLeaveTheFrame) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 1500, 4);
  const tsah::FlatBvh tree = sahTree(a, 4);
  tc::GpuRuntime gpu(tree, a);
  const ShutterKeys keys = shutterKeys(a, a.startTime(), a.endTime());
  ASSERT_GE(keys.fractions.size(), 3u);
  gpu.updateShutter(keys.fractions, keys.spans());
  const tsah::FlatBvh before = gpu.downloadKeyTree(1);
  const auto spans = keys.spans();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<float> times = keys.fractions;
  EXPECT_THROW(gpu.updateShutter({}, {}), tsah::ConfigError);
  EXPECT_THROW(gpu.updateShutter(std::span(times).first(2), spans), tsah::ConfigError);  // count mismatch
  for (auto edit : {std::pair{0, 0.1f}, std::pair{-1, 0.9f}, std::pair{1, 0.0f}, std::pair{1, nan}, std::pair{1, 1.5f}}) {
    times = keys.fractions;
    times[edit.first < 0 ? times.size() - 1 : std::size_t(edit.first)] = edit.second;
    EXPECT_THROW(gpu.updateShutter(times, spans), tsah::ConfigError) << edit.first << " -> " << edit.second;
  }
  std::vector<std::span<const float>> shortKey = spans;
  shortKey[1] = shortKey[1].first(shortKey[1].size() - 3);
  EXPECT_THROW(gpu.updateShutter(keys.fractions, shortKey), tsah::DataError);
  ASSERT_TRUE(gpu.blurred());
  EXPECT_EQ(gpu.shutterKeyCount(), keys.fractions.size());
  expectSameTree(gpu.downloadKeyTree(1), before, "key 1 after refused calls");
}

TEST(CudaMotionBlur, TheCompressedLayoutRefusesABlurredFrame) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 1500, 4);
  tc::GpuRuntime gpu(sahTree(a, 4), a, tsah::test::gpuConfig(tsah::Layout::Cwbvh));
  const ShutterKeys keys = shutterKeys(a, a.startTime(), a.endTime());
  try {
    gpu.updateShutter(keys.fractions, keys.spans());
    FAIL() << "layout cwbvh traced a blurred frame";
  } catch (const tsah::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("motion blur traces the binary layout on the GPU"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(gpu.updateShutterAt(a.startTime(), a.endTime()), tsah::ConfigError);
  EXPECT_FALSE(gpu.blurred());
  const std::vector<std::span<const float>> one{keys.positions[0]};
  EXPECT_NO_THROW(gpu.updateShutter(std::vector<float>{0.0f}, one));  // one key: a plain update
}

}  // namespace

#else

TEST(CudaMotionBlur, NotBuilt) { GTEST_SKIP() << "built without the CUDA runtime"; }

#endif
