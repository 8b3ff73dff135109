// The compressed 8-wide layout on the GPU (GpuRuntime with Config::layout = cwbvh): the refitted
// and re-quantized nodes equal tsah::refitCwbvh's byte for byte; closest and any hits equal the
// CPU reference traversal of the same layout exactly, and the binary GPU path up to ties; rendered
// images equal the binary path's and the CPU renderer's within the CPU/GPU tolerance. Skipped
// without a device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cmath>
#include <cstring>
#include <random>
#include <span>
#include <vector>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/render/sampling.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

using tsah::Vec3;
namespace tc = tsah::cuda;

using tsah::test::generatedAnimation;

using tsah::test::cwbvhWoop;
using tsah::test::GpuHits;
using tsah::test::traceHits;

// Sweep SAH on `keyframe`, collapsed to leaves of up to 8 triangles, boxes of every keyframe.
tsah::FlatBvh sahTree(const anim::Animation& a, uint32_t keyframe = 0) {
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(a.indices(), a.allPositions(), a.keyframeCount());
  tsah::Bvh bvh = tsah::SweepSahBuilder().build(boxes.frame(keyframe));
  tsah::LeafCollapser::Config c;
  c.maxLeafSize = 8;
  bvh = tsah::LeafCollapser(c).collapse(bvh);
  tsah::refit(bvh, boxes);
  return tsah::flattenBvh(bvh);
}

tc::GpuRuntime::Config wide() { return tsah::test::gpuConfig(tsah::Layout::Cwbvh); }

std::vector<tsah::Ray> randomRays(const tsah::Aabb& b, const anim::Animation& a, std::span<const float> pos,
                                  uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g;
  std::uniform_real_distribution<float> u01(0, 1);
  auto unit = [&] { return tsah::normalize(Vec3{g(rng), g(rng), g(rng)}); };
  const float diag = std::sqrt(tsah::dot(b.extent(), b.extent()));
  std::vector<tsah::Ray> rays(count);
  for (uint32_t i = 0; i < count; ++i) {
    tsah::Ray& r = rays[i];
    if (i % 3 == 0) {  // from outside at a triangle
      const uint32_t* tri = a.indices().data() + 3 * (rng() % a.triangleCount());
      Vec3 c{0, 0, 0};
      for (int k = 0; k < 3; ++k) c = c + Vec3{pos[3 * tri[k]], pos[3 * tri[k] + 1], pos[3 * tri[k] + 2]} * (1.0f / 3);
      r.org = b.center() + unit() * diag;
      r.dir = c - r.org;
    } else {  // from inside, any direction
      r.org = b.lo + Vec3{u01(rng) * b.extent().x, u01(rng) * b.extent().y, u01(rng) * b.extent().z};
      r.dir = unit() * (0.1f + 3.0f * u01(rng));
    }
    r.tmin = i % 5 == 2 ? 0.01f * u01(rng) : 0.0f;
    r.tmax = i % 4 == 0 ? 2.0f * u01(rng) : 3.4e38f;
  }
  return rays;
}

TEST(CudaCwbvh, NodesEqualHostRefitAtEveryTime) {
  REQUIRE_GPU();
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave}) {
    const anim::Animation a = generatedAnimation(kind, 6000, 6);
    const tsah::FlatBvh tree = sahTree(a);
    tc::GpuRuntime gpu(tree, a, wide());
    tsah::CwbvhTree host = tsah::buildCwbvh(tree);
    for (double t : {a.startTime(), 1.0, 2.5, a.endTime() + 1.0}) {
      gpu.updateAt(t);
      tsah::refitCwbvh(host, a.indices(), a.positionsAt(t));
      ASSERT_EQ(tsah::validateCwbvh(host), std::nullopt);
      const std::vector<tsah::CwbvhNode> nodes = gpu.downloadCwbvhNodes();
      ASSERT_EQ(nodes.size(), host.nodes.size());
      ASSERT_EQ(std::memcmp(nodes.data(), host.nodes.data(), nodes.size() * sizeof(tsah::CwbvhNode)), 0) << "t=" << t;
      const tsah::Aabb b = gpu.bounds();
      EXPECT_TRUE(b.contains(host.rootBox) && host.rootBox.contains(b));
    }
  }
}

// Config::wideObjective reaches the 8-wide collapse of the uploaded tree: the compressed nodes are
// the ones the host's collapse makes for that objective (WideCollapser(wideCollapseConfig(objective,
// 8)), as the CPU wide layouts), refitted at every time, with the Woop triangles in its slot order.
// The input is wideObjectiveCase (k = 2, cT = 4, cI = 1, leaves of at most 6), whose tree differs
// from the default objective's (asserted here; CwbvhBuild.EveryPartOfTheObjectiveShapesTheTree in
// test_cwbvh shows that k, the constants and the leaf limit each matter), so a runtime that dropped
// the objective would fail; a runtime with the default objective holds the default tree.
TEST(CudaCwbvh, CollapseFollowsTheObjective) {
  REQUIRE_GPU();
  using tsah::test::hostCwbvh;
  const tsah::test::WideObjectiveCase c = tsah::test::wideObjectiveCase();
  const anim::Animation& a = c.animation;
  tsah::CwbvhTree host = hostCwbvh(c.tree, c.objective);
  tsah::CwbvhTree hostDefault = hostCwbvh(c.tree, tsah::Objective{});
  ASSERT_FALSE(tsah::test::sameCwbvh(host, hostDefault));
  tc::GpuRuntime::Config config = wide();
  config.wideObjective = c.objective;
  tc::GpuRuntime gpu(c.tree, a, config);
  tc::GpuRuntime gpuDefault(c.tree, a, wide());
  EXPECT_EQ(gpu.config().wideObjective.k, c.objective.k);
  for (double t : {a.startTime(), 0.5 * (a.startTime() + a.endTime()), a.endTime()}) {
    const auto pos = a.positionsAt(t);
    for (auto [runtime, tree] : {std::pair{&gpu, &host}, std::pair{&gpuDefault, &hostDefault}}) {
      const bool isDefault = runtime == &gpuDefault;
      runtime->updateAt(t);
      tsah::refitCwbvh(*tree, a.indices(), pos);
      ASSERT_EQ(tsah::validateCwbvh(*tree), std::nullopt);
      const std::vector<tsah::CwbvhNode> nodes = runtime->downloadCwbvhNodes();
      ASSERT_EQ(nodes.size(), tree->nodes.size()) << "t=" << t << " default " << isDefault;
      EXPECT_EQ(std::memcmp(nodes.data(), tree->nodes.data(), nodes.size() * sizeof(tsah::CwbvhNode)), 0)
          << "t=" << t << " default " << isDefault;
      const std::vector<tsah::WoopTriangle> woop = cwbvhWoop(*tree, a.indices(), pos);
      const std::vector<tsah::WoopTriangle> deviceWoop = runtime->downloadWoop();
      ASSERT_EQ(deviceWoop.size(), woop.size());
      EXPECT_EQ(std::memcmp(deviceWoop.data(), woop.data(), woop.size() * sizeof woop[0]), 0)
          << "t=" << t << " default " << isDefault;
      const tsah::Aabb b = runtime->bounds();
      EXPECT_TRUE(b.contains(tree->rootBox) && tree->rootBox.contains(b)) << "t=" << t << " default " << isDefault;
    }
  }
}

// A tree set with build infos (one per tree, as a .tbvh file gives) collapses each tree with its
// own objective, whatever Config::wideObjective says; without build infos every tree follows
// Config::wideObjective. Build infos for only some trees are refused.
TEST(CudaCwbvh, TreeSetCollapsesEachTreeWithItsOwnObjective) {
  REQUIRE_GPU();
  using tsah::test::hostCwbvh;
  const tsah::test::WideObjectiveCase c = tsah::test::wideObjectiveCase();
  const anim::Animation& a = c.animation;
  const tsah::TreeSet set = tsah::test::twoPartObjectiveSet(c);  // tree 1 keeps the default objective
  tc::GpuRuntime::Config config = wide();
  config.wideObjective = tsah::Objective{1, {2.0f, 1.0f}, 3};
  const tsah::Objective ownObjectives[2] = {c.objective, tsah::Objective{}};
  for (const tsah::Objective& own : ownObjectives)
    ASSERT_FALSE(tsah::test::sameCwbvh(hostCwbvh(c.tree, own), hostCwbvh(c.tree, config.wideObjective)));
  tsah::TreeSet bare = set;
  bare.builds.clear();
  tc::GpuRuntime withBuilds(set, a, config);
  tc::GpuRuntime withoutBuilds(bare, a, config);
  for (double t : {a.startTime(), a.endTime()}) {
    const uint32_t s = set.treeAt(t);
    const auto pos = a.positionsAt(t);
    for (tc::GpuRuntime* runtime : {&withBuilds, &withoutBuilds}) {
      const bool builds = runtime == &withBuilds;
      runtime->updateAt(t);
      ASSERT_EQ(runtime->currentTree(), s);
      tsah::CwbvhTree host = hostCwbvh(set.trees[s], builds ? ownObjectives[s] : config.wideObjective);
      tsah::refitCwbvh(host, a.indices(), pos);
      const std::vector<tsah::CwbvhNode> nodes = runtime->downloadCwbvhNodes();
      ASSERT_EQ(nodes.size(), host.nodes.size()) << "t=" << t << " builds " << builds;
      EXPECT_EQ(std::memcmp(nodes.data(), host.nodes.data(), nodes.size() * sizeof(tsah::CwbvhNode)), 0)
          << "t=" << t << " builds " << builds;
    }
  }
  tsah::TreeSet partial = set;
  partial.builds.resize(1);
  EXPECT_THROW(tc::GpuRuntime(partial, a, config), tsah::Error);
}

// A tree without nodes (its root is one leaf of a few triangles): the refit forms the root box as
// tsah::refitCwbvh does, and the hits are the CPU reference traversal's.
TEST(CudaCwbvh, TreeThatIsOneLeaf) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 6, 4);
  ASSERT_LE(a.triangleCount(), 8u);  // one leaf of the collapse (leaves of up to 8)
  const tsah::FlatBvh tree = tsah::test::singleLeafTree(a);
  tsah::CwbvhTree host = tsah::buildCwbvh(tree);
  ASSERT_TRUE(tsah::isLeafRef(host.rootRef));
  ASSERT_EQ(host.nodeCount(), 0u);
  tc::GpuRuntime gpu(tree, a, wide());
  for (double t : {a.startTime(), 0.4 * a.endTime(), a.endTime()}) {
    gpu.updateAt(t);
    const auto pos = a.positionsAt(t);
    tsah::refitCwbvh(host, a.indices(), pos);
    const tsah::Aabb b = gpu.bounds();
    ASSERT_TRUE(b.contains(host.rootBox) && host.rootBox.contains(b)) << "t=" << t;
    const std::vector<tsah::WoopTriangle> woop = cwbvhWoop(host, a.indices(), pos);
    const tsah::CwbvhView view = host.view(woop.data(), a.indices().data(), pos.data());
    const auto rays = randomRays(b, a, pos, 3000, 7);
    const auto hits = gpu.closestHits(rays);
    const auto any = gpu.anyHits(rays);
    uint32_t valid = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      const tsah::Hit ref = tsah::cwbvhClosestHit(view, rays[i]);
      ASSERT_EQ(std::memcmp(&ref, &hits[i], sizeof ref), 0) << "ray " << i << " t=" << t;
      ASSERT_EQ(any[i] != 0, tsah::cwbvhAnyHit(view, rays[i])) << "ray " << i << " t=" << t;
      valid += ref.valid() ? 1 : 0;
    }
    EXPECT_GT(valid, 300u) << "t=" << t;
  }
}

TEST(CudaCwbvh, HitsEqualCpuReferenceAndBinaryGpu) {
  REQUIRE_GPU();
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave, anim::GeneratorKind::Swap}) {
    const anim::Animation a = generatedAnimation(kind, 8000, 6);
    const tsah::FlatBvh tree = sahTree(a);
    tc::GpuRuntime gpuWide(tree, a, wide());
    tc::GpuRuntime::Config persistentConfig = wide();
    persistentConfig.persistentTraversal = true;
    tc::GpuRuntime gpuWidePersistent(tree, a, persistentConfig);
    tc::GpuRuntime gpuBinary(tree, a);
    tsah::CwbvhTree host = tsah::buildCwbvh(tree);
    tsah::test::HitAgreement count;
    for (double t : {0.0, 2.3}) {
      gpuWide.updateAt(t);
      gpuWidePersistent.updateAt(t);
      gpuBinary.updateAt(t);
      const auto pos = a.positionsAt(t);
      tsah::refitCwbvh(host, a.indices(), pos);
      const std::vector<tsah::WoopTriangle> woop = cwbvhWoop(host, a.indices(), pos);
      EXPECT_EQ(std::memcmp(woop.data(), gpuWide.downloadWoop().data(), woop.size() * sizeof woop[0]), 0);
      const tsah::CwbvhView view = host.view(woop.data(), a.indices().data(), pos.data());
      const auto rays = randomRays(gpuBinary.bounds(), a, pos, 20000, 11);
      const GpuHits wideHits = traceHits(gpuWide, rays), binaryHits = traceHits(gpuBinary, rays);
      // Persistent threads (rays taken from a counter as lanes finish): the same results, ray by ray.
      const GpuHits persistent = traceHits(gpuWidePersistent, rays);
      ASSERT_EQ(std::memcmp(persistent.closest.data(), wideHits.closest.data(),
                            wideHits.closest.size() * sizeof wideHits.closest[0]),
                0);
      ASSERT_EQ(persistent.any, wideHits.any);
      ASSERT_NO_FATAL_FAILURE(tsah::test::expectWideHitsMatch(view, rays, wideHits, binaryHits, count));
    }
    EXPECT_GT(count.hits, 10000u);
    EXPECT_LE(count.ties, count.hits / 100) << "ties";
  }
}

// A tree set in the compressed layout: every tree gets its own compressed nodes; updateAt traces the
// tree of the frame's part, with the hits of the binary runtime over the same set.
TEST(CudaCwbvh, TreeSetTracesTheTreeOfEachPartLikeTheBinaryLayout) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Explode, 4000, 6);
  tsah::TreeSet set;
  for (uint32_t k : {0u, 3u}) set.trees.push_back(sahTree(a, k));
  const double mid = 0.5 * (a.startTime() + a.endTime());
  set.ranges = {{a.startTime(), mid}, {mid, a.endTime()}};
  tc::GpuRuntime gpuWide(set, a, wide());
  tc::GpuRuntime gpuBinary(set, a, tc::GpuRuntime::Config{});
  for (double t : {a.startTime(), mid - 0.1, mid + 0.1, a.endTime()}) {
    gpuWide.updateAt(t);
    gpuBinary.updateAt(t);
    ASSERT_EQ(gpuWide.currentTree(), set.treeAt(t)) << "t=" << t;
    // The compressed nodes are those of the part's tree, refitted to t.
    tsah::CwbvhTree host = tsah::buildCwbvh(set.trees[set.treeAt(t)]);
    tsah::refitCwbvh(host, a.indices(), a.positionsAt(t));
    const std::vector<tsah::CwbvhNode> nodes = gpuWide.downloadCwbvhNodes();
    ASSERT_EQ(nodes.size(), host.nodes.size()) << "t=" << t;
    EXPECT_EQ(std::memcmp(nodes.data(), host.nodes.data(), nodes.size() * sizeof(tsah::CwbvhNode)), 0) << "t=" << t;
    const auto rays = randomRays(gpuBinary.bounds(), a, a.positionsAt(t), 5000, 3);
    const auto wideHits = gpuWide.closestHits(rays), binaryHits = gpuBinary.closestHits(rays);
    const auto wideAny = gpuWide.anyHits(rays), binaryAny = gpuBinary.anyHits(rays);
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(wideAny[i], binaryAny[i]) << "t=" << t << " ray " << i;
      ASSERT_EQ(wideHits[i].valid(), binaryHits[i].valid()) << "t=" << t << " ray " << i;
      if (wideHits[i].valid()) {
        ASSERT_EQ(wideHits[i].t, binaryHits[i].t) << "t=" << t << " ray " << i;
      }
    }
  }
}

TEST(CudaCwbvh, ImagesEqualBinaryAndCpu) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Explode, 20000, 5);
  const tsah::FlatBvh tree = sahTree(a);
  tsah::CpuRuntime cpu(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  tc::GpuRuntime gpuWide(tree, a, wide());
  tc::GpuRuntime gpuBinary(tree, a);
  auto [bounds, settings, camera] = tsah::test::renderView(a);
  tsah::Camera away = camera;  // sees none of the mesh: the AO and shadow passes get an empty pixel list
  away.lookAt = camera.eye + (camera.eye - camera.lookAt);
  // With the ground every pixel below the horizon has a surface; without it the listed passes run
  // over the few pixels that see the mesh; looking away, over none.
  struct View {
    tsah::Camera camera;
    bool ground;
  };
  const View views[] = {{camera, true}, {camera, false}, {away, false}};
  for (const View& view : views) {
    const tsah::SceneLighting lighting = tsah::fitLighting(bounds, camera, {0, 1, 0}, 0.1f, view.ground);
    const bool seesMesh = &view != &views[2];
    for (uint32_t frame : {0u, 3u}) {
      settings.frame = frame;
      const double t = a.uniformTimes(5)[frame];
      cpu.update(a.positionsAt(t));
      gpuWide.updateAt(t);
      gpuBinary.updateAt(t);
      tsah::Image cpuImage, wideImage, binaryImage;
      const tsah::RenderStats c = tsah::renderFrame(cpu, view.camera, lighting, settings, cpuImage);
      const tsah::RenderStats w = tc::renderFrameGpu(gpuWide, view.camera, lighting, settings, wideImage);
      const tsah::RenderStats b = tc::renderFrameGpu(gpuBinary, view.camera, lighting, settings, binaryImage);
      // Primary ties (another triangle at the same distance) change a pixel's normal, so the AO and
      // shadow ray counts may differ slightly, as between the CPU and GPU renderers.
      tsah::test::expectRayCountsClose(w, b);
      for (const tsah::Image* other : {&binaryImage, &cpuImage})
        tsah::test::expectImagesClose(wideImage, *other,
                                      "frame " + std::to_string(frame) + " ground " + std::to_string(view.ground));
      if (seesMesh) {
        EXPECT_GT(c.ao.rays, 0u);
        // Mesh only: a strict subset of the pixels has a surface (the list is neither empty nor all).
        if (!view.ground) {
          EXPECT_LT(w.ao.rays, uint64_t(settings.width) * settings.height * settings.aoSamples);
        }
      } else {
        EXPECT_EQ(w.ao.rays, 0u);
        EXPECT_EQ(c.ao.rays, 0u);
      }
    }
  }
}

// The fused passes (each thread makes its ray and traces it, secondary rays over the listed pixels,
// AO beside shadow) trace the same rays with the same traversal as the separate generation and trace
// kernels: identical images and ray counts in both layouts, with and without the ground, and for a
// camera that sees nothing (empty pixel list).
TEST(CudaRender, FusedPassesEqualSeparatePassesInBothLayouts) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Explode, 6000, 4);
  const tsah::FlatBvh tree = sahTree(a);
  auto [bounds, settings, camera] = tsah::test::renderView(a);
  tsah::Camera away = camera;
  away.lookAt = camera.eye + (camera.eye - camera.lookAt);
  for (const tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Cwbvh}) {
    tc::GpuRuntime::Config fusedConfig = tsah::test::gpuConfig(layout), separateConfig = fusedConfig;
    separateConfig.fusePasses = false;
    tc::GpuRuntime fused(tree, a, fusedConfig), separate(tree, a, separateConfig);
    for (const bool ground : {true, false}) {
      for (const tsah::Camera* view : {&camera, &away}) {
        const tsah::SceneLighting lighting = tsah::fitLighting(bounds, camera, {0, 1, 0}, 0.1f, ground);
        settings.frame = 2;
        const double t = a.uniformTimes(4)[2];
        fused.updateAt(t);
        separate.updateAt(t);
        tsah::Image fusedImage, separateImage;
        const tsah::RenderStats f = tc::renderFrameGpu(fused, *view, lighting, settings, fusedImage);
        const tsah::RenderStats s = tc::renderFrameGpu(separate, *view, lighting, settings, separateImage);
        const std::string what = std::string(tsah::name(layout)) + (ground ? " ground" : "") +
                                 (view == &away ? " looking away" : "");
        EXPECT_EQ(f.primary.rays, s.primary.rays) << what;
        EXPECT_EQ(f.ao.rays, s.ao.rays) << what;
        EXPECT_EQ(f.shadow.rays, s.shadow.rays) << what;
        EXPECT_TRUE(fusedImage.rgb == separateImage.rgb) << what;
        if (view == &camera) EXPECT_GT(f.ao.rays, 0u) << what;
      }
    }
  }
}

// The GPU traces bvh2 and cwbvh; a CPU layout is refused, Auto is the default (bvh2).
TEST(CudaCwbvh, RefusesTheCpuLayouts) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 500, 3);
  const tsah::FlatBvh tree = sahTree(a);
  for (tsah::Layout layout : {tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
    tc::GpuRuntime::Config config;
    config.layout = layout;
    EXPECT_THROW(tc::GpuRuntime(tree, a, config), tsah::ConfigError) << tsah::name(layout);
  }
  tc::GpuRuntime::Config automatic;
  automatic.layout = tsah::Layout::Auto;
  EXPECT_EQ(tc::GpuRuntime(tree, a, automatic).config().layout, tsah::Layout::Bvh2);
}

}  // namespace

#else
TEST(CudaCwbvh, NotBuilt) { GTEST_SKIP() << "built without CUDA"; }
#endif
