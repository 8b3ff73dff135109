// Motion blur on the CUDA runtime: updateShutter refits the tree at every key of a shutter, and
// each key's boxes and positions equal the CPU runtime's update at that key's positions bit for bit
// (the same refit from the same positions); an update or rebuild ends the blurred frame; bad keys
// and the compressed layout are refused. Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "anim/generators.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/sah_builder.hpp"
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
  std::vector<double> times{open};
  for (double t : a.times())
    if (t > open && t < close) times.push_back(t);
  times.push_back(close);
  ShutterKeys keys;
  for (std::size_t k = 0; k < times.size(); ++k) {
    keys.fractions.push_back(k + 1 == times.size() ? 1.0f : float((times[k] - open) / (close - open)));
    keys.positions.push_back(a.positionsAt(times[k]));
  }
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
