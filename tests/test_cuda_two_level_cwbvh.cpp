// The GPU two-level runtime with its BLAS in the compressed 8-wide layout
// (GpuTwoLevelRuntime::Config::layout cwbvh): every pose's nodes equal tsah::refitCwbvh's of the
// host collapse at the pose's local time, byte for byte; the hits are the CPU runtime's (bvh2 BLAS)
// in instant and blurred frames; held poses are left as they are. The layouts visit triangles in
// different orders, so two surfaces at the same distance may be reported either way: a hit agrees
// when it names the CPU's instance and triangle with t within kRelativeT, and is a tie when it
// names another with t within the tolerance; ties may be at most 2% of the hits. Any hits must
// agree exactly. Every test but the refusals skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <algorithm>
#include <cstring>
#include <span>
#include <string>

#include "anim/animation.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "cuda_test_support.hpp"
#include "cuda_two_level_fixture.hpp"
#include "test_support.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

constexpr float kRelativeT = 1e-5f;

tsah::cuda::GpuTwoLevelRuntime::Config compressed() {
  tsah::cuda::GpuTwoLevelRuntime::Config config;
  config.layout = tsah::Layout::Cwbvh;
  return config;
}

tsah::TwoLevelRuntime cpuReference(const tsah::TwoLevelScene& scene) {
  return tsah::TwoLevelRuntime(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
}

// Counts hits, ties and any-hit checks of one ray set against the CPU runtime (see the top).
struct Agreement {
  uint32_t rays = 0, hits = 0, ties = 0;

  void add(const tsah::TwoLevelHit& got, const tsah::TwoLevelHit& expected, const std::string& where) {
    ++rays;
    ASSERT_EQ(got.valid(), expected.valid()) << where;
    if (!expected.valid()) return;
    ++hits;
    EXPECT_NEAR(got.t, expected.t, kRelativeT * std::max(1.0f, expected.t)) << where;
    if (got.instance != expected.instance || got.prim != expected.prim) ++ties;
  }
  void expectFewTies() const {
    EXPECT_GT(hits, rays / 4);  // the comparison saw real hits
    EXPECT_LE(ties, hits / 50) << ties << " ties in " << hits << " hits";
  }
};

// Closest and any hits of rays through the instances' boxes at the runtimes' current time.
void compareHits(tsah::cuda::GpuTwoLevelRuntime& gpu, const tsah::TwoLevelRuntime& cpu, uint32_t seed,
                 Agreement& agreement, const std::string& where) {
  const std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(tsah::test::unionOf(cpu.instanceBoxes()), 2000, seed);
  const std::vector<tsah::TwoLevelHit> got = gpu.closestHits(rays);
  const std::vector<uint8_t> occluded = gpu.anyHits(rays);
  for (std::size_t r = 0; r < rays.size(); ++r) {
    const std::string at = where + " ray " + std::to_string(r);
    agreement.add(got[r], cpu.closestHit(rays[r]), at);
    EXPECT_EQ(occluded[r] != 0, cpu.anyHit(rays[r])) << at;
  }
}

// Every pose's nodes after each update against the host: the source's tree collapsed with the
// objective it was built with, refitted at the pose's local time.
void expectPosesEqualTheHostRefit(const tsah::TwoLevelScene& scene, std::span<const double> times) {
  tsah::cuda::GpuTwoLevelRuntime gpu(scene, compressed());
  const anim::SceneSources& src = scene.scene;
  ASSERT_FALSE(scene.poses.empty());
  for (const double t : times) {
    gpu.updateAt(t);
    for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
      const uint32_t p = scene.instancePose[i];
      if (p == tsah::kInvalidIndex) continue;
      const tsah::Blas& blas = scene.blases[scene.poses[p].blas];
      const anim::Animation& a = *src.sources[blas.source];
      tsah::Objective objective = scene.objective;
      objective.k = blas.animated ? objective.k : 0;
      tsah::CwbvhTree host = tsah::buildCwbvh(blas.flat, objective);
      tsah::refitCwbvh(host, a.indices(), a.positionsAt(src.instances[i].localTime(t, a)));
      ASSERT_EQ(tsah::validateCwbvh(host), std::nullopt);
      const tsah::CwbvhTree device = gpu.downloadPoseCwbvh(p);
      ASSERT_EQ(device.nodes.size(), host.nodes.size());
      EXPECT_EQ(device.triIndex, host.triIndex);
      EXPECT_EQ(std::memcmp(device.nodes.data(), host.nodes.data(), host.nodes.size() * sizeof(tsah::CwbvhNode)), 0)
          << "t " << t << " pose " << p;
      EXPECT_EQ(std::memcmp(&device.rootBox, &host.rootBox, sizeof(tsah::Aabb)), 0) << "t " << t << " pose " << p;
    }
  }
}

using CudaTwoLevelCwbvh = tsah::test::GpuTwoLevelSceneTest;

TEST_F(CudaTwoLevelCwbvh, PosesEqualTheHostRefitAtEveryTime) {
  const double times[] = {0.0, 2.0, 3.25, 7.5, 12.0, 3.25};
  expectPosesEqualTheHostRefit(*scene, times);
}

TEST_F(CudaTwoLevelCwbvh, CrowdPosesEqualTheHostRefit) {
  const tsah::TwoLevelScene crowd =
      tsah::loadTwoLevelScene(tsah::test::writeCrowdScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  ASSERT_EQ(crowd.poses.size(), 48u);
  const double times[] = {0.0, 1.5, 9.75};
  expectPosesEqualTheHostRefit(crowd, times);
}

TEST_F(CudaTwoLevelCwbvh, HitsAsTheCpuRuntimeAtSeveralTimes) {
  const tsah::TwoLevelScene crowd =
      tsah::loadTwoLevelScene(tsah::test::writeCrowdScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  for (const tsah::TwoLevelScene* s : {const_cast<const tsah::TwoLevelScene*>(scene.get()), &crowd}) {
    tsah::TwoLevelRuntime cpu = cpuReference(*s);
    tsah::cuda::GpuTwoLevelRuntime gpu(*s, compressed());
    Agreement agreement;
    for (const double t : {0.0, 2.0, 3.25, 3.25, 7.5, 12.0}) {  // 3.25 twice: the second update moves no pose
      cpu.update(t);
      gpu.updateAt(t);
      compareHits(gpu, cpu, uint32_t(t * 4) + 1, agreement, "instances " + std::to_string(s->instanceCount()) +
                                                                " t " + std::to_string(t));
    }
    agreement.expectFewTies();
  }
}

// The same TLAS over the same instance boxes whatever the BLAS layout: the compressed root boxes
// are the exact boxes of the poses' triangles, as the binary refit's (the keyed update's lerped
// boxes would be looser).
TEST_F(CudaTwoLevelCwbvh, InstanceBoxesEqualTheBinaryLayouts) {
  tsah::cuda::GpuTwoLevelRuntime::Config refit;
  refit.keyedPoses = false;
  tsah::cuda::GpuTwoLevelRuntime binary(*scene, refit);
  tsah::cuda::GpuTwoLevelRuntime wide(*scene, compressed());
  for (const double t : scene->frameTimes) {
    binary.updateAt(t);
    wide.updateAt(t);
    const std::vector<tsah::Aabb> a = binary.downloadInstanceBoxes(), b = wide.downloadInstanceBoxes();
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(tsah::Aabb)), 0) << "t " << t;
  }
}

// Held poses (their local time unchanged) are neither interpolated nor refitted: the counts are
// the binary layout's, and the held poses keep their last frame (the hits are the CPU's).
TEST(CudaTwoLevelCwbvhRigid, AHeldPoseIsLeftAsItIsWhileAnotherMoves) {
  REQUIRE_GPU();
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeRigidPathScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  tsah::TwoLevelRuntime cpu = cpuReference(s);
  tsah::cuda::GpuTwoLevelRuntime gpu(s, compressed());
  EXPECT_EQ(gpu.blasRefits(), 2u);  // both poses at the first frame
  gpu.updateAt(3.0);
  cpu.update(3.0);
  Agreement agreement;
  const std::pair<double, uint32_t> steps[] = {{4.25, 2u}, {4.5, 1u}, {4.75, 1u}, {5.0, 1u}, {5.5, 0u}, {7.0, 0u}};
  for (const auto& [t, refits] : steps) {
    EXPECT_EQ(gpu.updateAt(t).blasRefits, refits) << "t " << t;
    cpu.update(t);
    compareHits(gpu, cpu, uint32_t(t * 4) + 7, agreement, "t " + std::to_string(t));
  }
  agreement.expectFewTies();
}

// A blurred frame: the moving poses in the blurred layout, the held ones and the static BLAS in
// the compressed one, at each ray's time.
TEST_F(CudaTwoLevelCwbvh, BlurredFramesHitAsTheCpuRuntime) {
  tsah::TwoLevelRuntime cpu = cpuReference(*scene);
  tsah::cuda::GpuTwoLevelRuntime gpu(*scene, compressed());
  Agreement agreement;
  for (const auto& [open, close] : {std::pair{2.75, 3.25}, std::pair{9.0, 11.5}}) {
    cpu.updateShutter(open, close);
    gpu.updateShutter(open, close);
    ASSERT_TRUE(cpu.blurred() && gpu.blurred());
    const std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(tsah::test::unionOf(cpu.instanceBoxes()), 2000, 5);
    std::vector<float> times(rays.size());
    for (std::size_t r = 0; r < rays.size(); ++r) times[r] = float(r % 11) / 10.0f;
    const std::vector<tsah::TwoLevelHit> got = gpu.closestHits(rays, times);
    const std::vector<uint8_t> occluded = gpu.anyHits(rays, times);
    for (std::size_t r = 0; r < rays.size(); ++r) {
      const std::string at = "shutter " + std::to_string(open) + " ray " + std::to_string(r);
      agreement.add(got[r], cpu.closestHit(rays[r], times[r]), at);
      EXPECT_EQ(occluded[r] != 0, cpu.anyHit(rays[r], times[r])) << at;
    }
  }
  agreement.expectFewTies();
}

tsah::TwoLevelScene rigidScene() {
  return tsah::loadTwoLevelScene(tsah::test::writeRigidPathScene(tsah::test::scratchDir()).string(), {},
                                 tsah::test::smallTwoLevelOptions());
}

// The CPU's wide layouts are refused before the device is looked for, so on every machine.
TEST(CudaTwoLevelCwbvhConfig, RefusesTheCpuLayouts) {
  const tsah::TwoLevelScene s = rigidScene();
  for (const tsah::Layout layout : {tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
    tsah::cuda::GpuTwoLevelRuntime::Config config;
    config.layout = layout;
    try {
      tsah::cuda::GpuTwoLevelRuntime gpu(s, config);
      ADD_FAILURE() << tsah::name(layout) << " accepted";
    } catch (const tsah::ConfigError& e) {
      EXPECT_EQ(std::string(e.what()), std::string("GPU two-level runtime: ") + tsah::name(layout) +
                                           " is no GPU layout (bvh2 or cwbvh)");
    }
  }
}

// Each pose download serves its own layout.
TEST(CudaTwoLevelCwbvhConfig, EachPoseDownloadServesItsLayout) {
  REQUIRE_GPU();
  const tsah::TwoLevelScene s = rigidScene();
  tsah::cuda::GpuTwoLevelRuntime wide(s, compressed());
  EXPECT_THROW(wide.downloadPoseTree(0), tsah::ConfigError);
  EXPECT_NO_THROW(wide.downloadPoseCwbvh(0));
  EXPECT_THROW(wide.downloadPoseCwbvh(uint32_t(s.poses.size())), tsah::ConfigError);
  tsah::cuda::GpuTwoLevelRuntime binary(s);
  EXPECT_THROW(binary.downloadPoseCwbvh(0), tsah::ConfigError);
  EXPECT_NO_THROW(binary.downloadPoseTree(0));
}

}  // namespace

#endif  // TSAH_HAVE_CUDA
