// The CPU runtime benchmark (bench/runtime_bench.hpp runCpuMethods): every method traces every
// frame with the same workload, frame by frame, and keeps the picture asked for.
#include <gtest/gtest.h>

#include <algorithm>

#include "anim/generators.hpp"
#include "animation_frames.hpp"
#include "bench/embree_peer.hpp"
#include "bench/runtime_bench.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "bench_setup.hpp"
#include "test_support.hpp"

namespace {

using tsah::test::generatedAnimation;

// 48x36 pixels, 3 AO and 2 shadow rays per pixel, `frames` frames, a fixed fitted camera.
tsah::bench::RuntimeSetup smallSetup(const anim::Animation& a, uint32_t frames) {
  return tsah::test::smallBenchSetup(a, a.uniformTimes(frames), 48, 36, 3);
}

// A method of the Embree comparison that finds exactly what the toolkit finds: its hits_minus_toolkit
// are zero in every pass.
void expectSameHitsAsToolkit(const nlohmann::json& extra, const std::string& name) {
  for (const char* pass : {"primary", "ao_occluded", "shadow_occluded"})
    EXPECT_EQ(extra["hits_minus_toolkit"][pass], 0) << name << " " << pass;
}

TEST(BenchRuntime, EveryMethodTracesEveryFrameWithTheSameRays) {
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Swap, 1200, 5, 4);
  const anim::Animation rep = a.resample(3);
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(rep.indices(), rep.allPositions(), 3);
  tsah::BaselineConfig config;
  config.threads = 2;
  const tsah::Bvh sah0 = tsah::buildSah0(boxes, config);
  const tsah::Bvh tsah0 = tsah::buildTSah(boxes, 0, config);
  tsah::SegmentationConfig sc;
  sc.representativeFrames = 3;
  sc.evaluationFrames = 4;
  sc.baseline = config;
  const tsah::SegmentationResult parts = tsah::evaluateParts(
      tsah::cli::animationTimeline(a), tsah::equalTimeRanges(a.startTime(), a.endTime(), 2), sc);

  tsah::bench::RuntimeSetup setup = smallSetup(a, 4);
  const tsah::Camera camera = setup.camera(0.0);
  std::vector<std::string> progress;
  setup.progress = [&](const std::string& m) { progress.push_back(m); };

  using tsah::bench::CpuMethodSpec;
  using tsah::bench::CpuRebuild;
  std::vector<CpuMethodSpec> specs = {
      {{"sah0", "SAH0 refit", {&sah0}, {}}, std::nullopt},
      {{"tsah0", "T-SAH refit", {&tsah0}, {}}, std::nullopt},
      {{"tsah0-seg2", "T-SAH, 2 trees", {&parts.trees[0], &parts.trees[1]}, parts.buildRanges}, std::nullopt},
      {{"rebuild-sweep", "sweep", {&tsah0}, {}}, CpuRebuild::Sweep},
      {{"rebuild-binned", "binned", {&tsah0}, {}}, CpuRebuild::Binned},
  };
  tsah::Image picture;
  const auto methods = tsah::bench::runCpuMethods(a, specs, config.objective.cost, 8, setup, &picture, 1, 2);
  ASSERT_EQ(methods.size(), specs.size());
  EXPECT_FALSE(progress.empty());
  for (std::size_t m = 0; m < methods.size(); ++m) {
    EXPECT_EQ(methods[m].name, specs[m].trees.name);
    EXPECT_EQ(methods[m].update, specs[m].rebuild ? "rebuild" : "refit");
    ASSERT_EQ(methods[m].frames.size(), setup.times.size());
    for (std::size_t f = 0; f < setup.times.size(); ++f) {
      const tsah::bench::FrameTiming& ft = methods[m].frames[f];
      EXPECT_EQ(ft.time, setup.times[f]);
      EXPECT_GT(ft.updateMs, 0.0);
      EXPECT_DOUBLE_EQ(ft.traceMs, ft.rays.total().ms);
      EXPECT_DOUBLE_EQ(ft.totalMs, ft.updateMs + ft.traceMs);
      // Exact tracers on the same frame: every tree finds the same surfaces, so the same rays.
      const tsah::RenderStats& first = methods[0].frames[f].rays;
      EXPECT_EQ(ft.rays.primary.rays, 48u * 36u);
      EXPECT_EQ(ft.rays.ao.rays, first.ao.rays) << methods[m].name << " frame " << f;
      EXPECT_EQ(ft.rays.shadow.rays, first.shadow.rays) << methods[m].name << " frame " << f;
    }
  }
  EXPECT_GT(methods[0].frames[0].rays.ao.rays, 0u);

  // The picture is T-SAH's frame 2, as a runtime of that tree renders it.
  tsah::CpuRuntime rt(tsah::flattenBvh(tsah0), {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  rt.update(a.positionsAt(setup.times[2]));
  tsah::RenderSettings settings = setup.settings;
  settings.frame = 2;
  tsah::Image expected;
  tsah::renderFrame(rt, camera, setup.lighting, settings, expected);
  ASSERT_EQ(picture.width, 48u);
  EXPECT_EQ(picture.rgb, expected.rgb);

  const nlohmann::json j = tsah::bench::toJson(methods[2]);
  EXPECT_EQ(j["name"], "tsah0-seg2");
  EXPECT_EQ(j["per_frame"]["total_ms"].size(), 4u);
}

TEST(BenchRuntime, EmbreeComparisonTracesEveryLayoutWithTheSameResults) {
  if (!tsah::bench::embreeAvailable()) GTEST_SKIP() << tsah::bench::embreeStatus();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Explode, 900, 4);
  const anim::Animation rep = a.resample(3);
  tsah::BaselineConfig config;
  config.threads = 2;
  const tsah::Bvh tree = tsah::buildTSah(tsah::triangleBoxes(rep.indices(), rep.allPositions(), 3), 0, config);
  const tsah::bench::RuntimeSetup setup = smallSetup(a, 2);
  const auto methods = tsah::bench::runEmbreeComparison(a, tree, "tsah0", "toolkit", setup);
  std::vector<std::string> names;
  for (const auto& m : methods) names.push_back(m.name);
  ASSERT_FALSE(names.empty());
  EXPECT_EQ(names[0], std::string("tsah0-") + tsah::name(setup.layout));  // the default layout first
  for (const char* n : {"tsah0-bvh2", "embree-medium", "embree-high", "embree-refit"})
    EXPECT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
  for (const auto& m : methods) {
    ASSERT_EQ(m.frames.size(), 2u) << m.name;
    EXPECT_EQ(m.frames[0].rays.ao.rays, methods[0].frames[0].rays.ao.rays);  // the same batch
    if (m.name.rfind("tsah0-", 0) == 0 && m.name != names[0]) {
      // Every toolkit layout finds exactly what the default one finds.
      expectSameHitsAsToolkit(m.extra, m.name);
    }
    if (m.name.rfind("tsah0-", 0) == 0) {
      EXPECT_EQ(m.extra["layout"]["layout"], m.name.substr(6));
    }
  }
}

TEST(BenchRuntime, EmbreeComparisonTracesTheTreeSetSwitchingTreesWithTheSameResults) {
  if (!tsah::bench::embreeAvailable()) GTEST_SKIP() << tsah::bench::embreeStatus();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 900, 4);
  tsah::BaselineConfig config;
  config.threads = 2;
  const double mid = 0.5 * (a.startTime() + a.endTime());
  auto treeOver = [&](double t0, double t1) {  // a T-SAH tree of two frames of [t0, t1]
    std::vector<float> p = a.positionsAt(t0);
    const std::vector<float> q = a.positionsAt(t1);
    p.insert(p.end(), q.begin(), q.end());
    return tsah::buildTSah(tsah::triangleBoxes(a.indices(), p, 2), 0, config);
  };
  const tsah::Bvh whole = treeOver(a.startTime(), a.endTime());
  const tsah::Bvh first = treeOver(a.startTime(), mid), second = treeOver(mid, a.endTime());
  const tsah::bench::RefitTrees set{"tsah0-count2", "two trees", {&first, &second}, {{a.startTime(), mid}, {mid, a.endTime()}}};
  const tsah::bench::RuntimeSetup setup = smallSetup(a, 2);
  const auto methods = tsah::bench::runEmbreeComparison(a, whole, "tsah0", "toolkit", setup, &set);
  const auto it = std::find_if(methods.begin(), methods.end(),
                               [](const auto& m) { return m.name.rfind("tsah0-count2-", 0) == 0; });
  ASSERT_NE(it, methods.end());
  EXPECT_EQ(it->name, std::string("tsah0-count2-") + tsah::name(setup.layout));
  EXPECT_EQ(it->extra["trees"], 2);
  ASSERT_EQ(it->frames.size(), 2u);
  EXPECT_EQ(it->frames[1].rays.ao.rays, methods[0].frames[1].rays.ao.rays);  // the same batch
  expectSameHitsAsToolkit(it->extra, it->name);  // other trees over the same triangles: same answers
}

}  // namespace
