// The GPU runtime with a tree set: all trees uploaded once, updateAt(t) refits and traces the tree
// of t's part, exactly as the CPU runtime picks and refits it (boxes and Woop triangles bit for
// bit), boundaries and overlaps included; a blurred frame whose shutter crosses switch times traces
// each ray by the tree of its time, as the CPU runtime. Skips without a CUDA device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cstring>
#include <random>
#include <utility>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
#include "shutter_checks.hpp"
#include "test_support.hpp"

namespace {

namespace tc = tsah::cuda;

using tsah::test::generatedAnimation;

// Three different trees (sweep SAH on keyframes 0, 3 and 6, leaves of <= 4), overlapping ranges.
tsah::TreeSet makeSet(const anim::Animation& a) {
  tsah::TreeSet set;
  tsah::LeafCollapser::Config l;
  l.maxLeafSize = 4;
  for (uint32_t k : {0u, 3u, 6u}) {
    const tsah::Bvh bvh = tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, k));
    set.trees.push_back(tsah::flattenBvh(tsah::LeafCollapser(l).collapse(bvh)));
  }
  const double t0 = a.startTime(), d = (a.endTime() - a.startTime()) / 3.0;
  set.ranges = {{t0, t0 + 1.2 * d}, {t0 + 0.8 * d, t0 + 2 * d}, {t0 + 2 * d, a.endTime()}};
  return set;
}

TEST(CudaTreeSet, UpdateAtRefitsTheTreeOfEachFramesPartLikeTheCpuRuntime) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 2000, 8);
  const tsah::TreeSet set = makeSet(a);
  tc::GpuRuntime gpu(set, a, tc::GpuRuntime::Config{});
  tsah::CpuRuntime cpu(set, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  EXPECT_EQ(gpu.treeCount(), 3u);
  const double d = (a.endTime() - a.startTime()) / 3.0;
  const double switch0 = tsah::switchTime(set.ranges, 0), switch1 = tsah::switchTime(set.ranges, 1);
  const double times[] = {a.startTime(), std::nextafter(switch0, 0.0), switch0, a.startTime() + 1.5 * d,
                          switch1,       a.endTime(),                   a.startTime() + 0.1 * d};
  for (double t : times) {
    const uint32_t want = set.treeAt(t);
    gpu.updateAt(t);
    EXPECT_EQ(gpu.currentTree(), want) << "time " << t;
    EXPECT_EQ(cpu.selectTreeAt(t), want);
    cpu.update(a.positionsAt(t));
    const tsah::FlatBvh g = gpu.downloadTree();
    const tsah::FlatBvh& c = cpu.tree();
    EXPECT_EQ(g.triIndex, set.trees[want].triIndex) << "time " << t;
    ASSERT_EQ(g.nodes.size(), c.nodes.size()) << "time " << t;
    EXPECT_EQ(std::memcmp(g.nodes.data(), c.nodes.data(), g.nodes.size() * sizeof(tsah::GpuBvhNode)), 0) << t;
    const std::vector<tsah::WoopTriangle> woop = gpu.downloadWoop();
    ASSERT_EQ(woop.size(), cpu.woop().size());
    EXPECT_EQ(std::memcmp(woop.data(), cpu.woop().data(), cpu.woop().size_bytes()), 0) << "time " << t;
  }
  // update(positions) refits the tree chosen by selectTreeAt.
  EXPECT_EQ(gpu.selectTreeAt(a.startTime() + 1.5 * d), 1u);
  gpu.update(a.positionsAt(a.startTime()));
  EXPECT_EQ(gpu.downloadTree().triIndex, set.trees[1].triIndex);
}

// Shutters across one switch (two parts), across both (three) and inside one part after them: the
// GPU's parts, keys and current tree are the CPU runtime's, every ray's hit equals the CPU's at its
// time (whether it hits, the distance bit for bit, the triangle unless two lie at that distance),
// and the fused and separate render passes give the CPU renderer's image.
TEST(CudaTreeSet, BlurredFramesTraceEachRayByTheTreeOfItsTime) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 2000, 8);
  const tsah::TreeSet set = makeSet(a);
  tc::GpuRuntime::Config fusedConfig = tsah::test::gpuConfig(tsah::Layout::Bvh2), separateConfig = fusedConfig;
  fusedConfig.fusePasses = true;
  separateConfig.fusePasses = false;
  tc::GpuRuntime fused(set, a, fusedConfig), separate(set, a, separateConfig);
  tsah::CpuRuntime cpu(set, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  tsah::test::RenderView view = tsah::test::renderView(a);
  const tsah::SceneLighting lighting = tsah::fitLighting(view.bounds, view.camera);
  const double d = (a.endTime() - a.startTime()) / 3.0;
  const double switch0 = tsah::switchTime(set.ranges, 0), switch1 = tsah::switchTime(set.ranges, 1);
  const std::pair<double, double> shutters[] = {
      {switch0 - 0.3 * d, switch0 + 0.2 * d}, {switch0 - 0.2 * d, switch1 + 0.2 * d}, {switch1 + 0.1 * d, switch1 + 0.3 * d}};
  const uint32_t parts[] = {2, 3, 1};
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  for (int s = 0; s < 3; ++s) {
    const auto [open, close] = shutters[s];
    const std::string what = "shutter [" + std::to_string(open) + ", " + std::to_string(close) + "]";
    tsah::updateShutter(cpu, a, open, close);
    fused.updateShutterAt(open, close);
    separate.updateShutterAt(open, close);
    ASSERT_EQ(cpu.shutterPartCount(), parts[s]) << what;
    ASSERT_TRUE(fused.blurred()) << what;
    EXPECT_EQ(fused.currentTree(), cpu.currentTree()) << what;
    EXPECT_EQ(fused.shutterKeyCount(), cpu.shutterKeyCount()) << what;

    const std::vector<tsah::Ray> rays = tsah::test::raysAtRuntime(cpu, 3000, uint32_t(s) + 11);
    std::vector<float> times(rays.size());
    for (std::size_t i = 0; i < times.size(); ++i) {
      const uint32_t p = uint32_t(i % cpu.shutterPartCount());
      times[i] = i % 7 == 0 ? cpu.keyTimes(p).front() : u01(rng);  // part starts among them
    }
    const std::vector<tsah::Hit> hits = fused.closestHits(rays, times);
    const std::vector<uint8_t> occluded = fused.anyHits(rays, times);
    uint32_t found = 0, ties = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      const tsah::Hit want = cpu.closestHit(rays[i], times[i]);
      ASSERT_EQ(hits[i].valid(), want.valid()) << what << ", ray " << i << " at " << times[i];
      ASSERT_EQ(occluded[i] != 0, cpu.anyHit(rays[i], times[i])) << what << ", ray " << i;
      if (!want.valid()) continue;
      ++found;
      ASSERT_EQ(hits[i].t, want.t) << what << ", ray " << i << " at " << times[i];
      ties += hits[i].tri != want.tri ? 1 : 0;
    }
    EXPECT_GT(found, rays.size() / 10) << what;
    EXPECT_LE(ties, rays.size() / 100) << what;

    view.settings.frame = uint32_t(s);
    tsah::Image cpuImage, fusedImage, separateImage;
    tsah::renderFrame(cpu, view.camera, lighting, view.settings, cpuImage);
    tc::renderFrameGpu(fused, view.camera, lighting, view.settings, fusedImage);
    tc::renderFrameGpu(separate, view.camera, lighting, view.settings, separateImage);
    tsah::test::expectImagesClose(cpuImage, fusedImage, "fused, " + what);
    EXPECT_TRUE(fusedImage.rgb == separateImage.rgb) << "fused against separate passes, " << what;
  }
}

TEST(CudaTreeSet, RefusesAnEmptySetOrATreeOfOtherTriangles) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 500, 8);
  EXPECT_THROW(tc::GpuRuntime(tsah::TreeSet{}, a, tc::GpuRuntime::Config{}), tsah::Error);
  tsah::TreeSet set = makeSet(a);
  set.trees[2].triIndex.pop_back();
  EXPECT_THROW(tc::GpuRuntime(set, a, tc::GpuRuntime::Config{}), tsah::Error);
}

}  // namespace

#else
TEST(CudaTreeSet, NotBuilt) { GTEST_SKIP() << "built without CUDA"; }
#endif
