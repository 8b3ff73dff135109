// The GPU two-level runtime (tsah_cuda/gpu_two_level.hpp) against the CPU one (TwoLevelRuntime):
// the same hits (instance, triangle, t), TLAS boxes holding every instance, no BLAS refit on a
// frame of rigid motion only; the TLAS rebuilt every frame (LBVH, HLBVH-SAH) against the refitted
// one; a T-SAH TLAS that misses an instance refused by every TLAS update. Every test skips without
// a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <algorithm>
#include <cstring>
#include <random>
#include <span>

#include "anim/animation.hpp"
#include "anim/tanim.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "cuda_test_support.hpp"
#include "cuda_two_level_fixture.hpp"
#include "test_support.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

// Relative tolerance on t: both runtimes move the ray into instance space with the same float
// operations and run the same traversal; only the compilers' rounding of the transform may differ.
constexpr float kRelativeT = 1e-5f;

// The TLAS rebuilt at every update (LBVH and HLBVH-SAH) against the refitted T-SAH TLAS of the same
// scene, at `times` (a time twice in a row: the second update moves no pose): the same instance
// boxes, a valid rebuilt TLAS (leaves of at most the objective's leaf size, each leaf box holding
// its instances) and the same hits on the same rays.
void expectRebuiltTlasTracesLikeTheRefit(const tsah::TwoLevelScene& scene, std::span<const double> times,
                                         uint32_t seed) {
  tsah::cuda::GpuTwoLevelRuntime refit(scene);
  for (const auto update : {tsah::cuda::TlasUpdate::Lbvh, tsah::cuda::TlasUpdate::HlbvhSah}) {
    SCOPED_TRACE(tsah::cuda::tlasUpdateName(update));
    tsah::cuda::GpuTwoLevelRuntime::Config config;
    config.tlas = update;
    tsah::cuda::GpuTwoLevelRuntime rebuilt(scene, config);
    uint32_t hits = 0, total = 0;
    for (const double t : times) {
      refit.updateAt(t);
      const tsah::cuda::TwoLevelUpdateTimings u = rebuilt.updateAt(t);
      EXPECT_GT(u.tlasRebuildMs, 0.0) << "t " << t;
      EXPECT_LE(u.tlasRebuildMs, u.tlasMs + 1e-3) << "t " << t;
      const std::vector<tsah::Aabb> boxes = rebuilt.downloadInstanceBoxes(), refitBoxes = refit.downloadInstanceBoxes();
      ASSERT_EQ(boxes.size(), scene.instanceCount());
      EXPECT_EQ(std::memcmp(boxes.data(), refitBoxes.data(), boxes.size() * sizeof(tsah::Aabb)), 0) << "t " << t;

      const tsah::FlatBvh tlas = rebuilt.downloadTlas();
      ASSERT_EQ(tsah::validateFlatBvh(tlas), std::nullopt) << "t " << t;
      EXPECT_EQ(tlas.triangleCount(), scene.instanceCount());
      EXPECT_EQ(tlas.interiorCount, u.tlasNodes) << "t " << t;
      uint32_t largestLeaf = tlas.interiorCount == 0 ? tlas.rootCount : 0;
      for (const tsah::GpuBvhNode& n : tlas.nodes)
        for (int c = 0; c < 2; ++c) largestLeaf = std::max(largestLeaf, n.childCount(c));
      EXPECT_LE(largestLeaf, scene.objective.maxLeafSize) << "t " << t;
      const std::vector<tsah::Aabb> leafBoxes = tsah::test::tlasLeafBoxes(tlas);
      for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
        EXPECT_TRUE(leafBoxes[i].contains(boxes[i])) << "t " << t << " instance " << i;
        EXPECT_TRUE(tlas.rootBoxes[0].contains(boxes[i])) << "t " << t << " instance " << i;
      }

      const std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(tsah::test::unionOf(boxes), 2000, seed++);
      const std::vector<tsah::TwoLevelHit> got = rebuilt.closestHits(rays), expected = refit.closestHits(rays);
      const std::vector<uint8_t> occluded = rebuilt.anyHits(rays), expectedOccluded = refit.anyHits(rays);
      for (std::size_t r = 0; r < rays.size(); ++r, ++total) {
        ASSERT_EQ(got[r].valid(), expected[r].valid()) << "t " << t << " ray " << r;
        EXPECT_EQ(occluded[r], expectedOccluded[r]) << "t " << t << " ray " << r;
        if (!expected[r].valid()) continue;
        ++hits;
        EXPECT_EQ(got[r].instance, expected[r].instance) << "t " << t << " ray " << r;
        EXPECT_EQ(got[r].prim, expected[r].prim) << "t " << t << " ray " << r;
        EXPECT_NEAR(got[r].t, expected[r].t, kRelativeT * std::max(1.0f, expected[r].t)) << "t " << t << " ray " << r;
      }
    }
    EXPECT_GT(hits, total / 4);  // the comparison saw real hits
  }
}

using CudaTwoLevel = tsah::test::GpuTwoLevelSceneTest;

// Closest hits (instance, triangle, t) and any hits of the GPU runtime equal the CPU runtime's at
// several scene times.
void expectCpuHits(const tsah::TwoLevelScene& twoLevel) {
  tsah::TwoLevelRuntime cpu(twoLevel, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::cuda::GpuTwoLevelRuntime gpu(twoLevel);
  uint32_t hits = 0, total = 0;
  for (const double t : {0.0, 2.0, 3.25, 7.5, 10.0, 12.0}) {
    cpu.update(t);
    gpu.updateAt(t);
    const std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(tsah::test::unionOf(cpu.instanceBoxes()), 2000, uint32_t(t * 4) + 1);
    const std::vector<tsah::TwoLevelHit> got = gpu.closestHits(rays);
    const std::vector<uint8_t> occluded = gpu.anyHits(rays);
    ASSERT_EQ(got.size(), rays.size());
    for (std::size_t r = 0; r < rays.size(); ++r, ++total) {
      const tsah::TwoLevelHit expected = cpu.closestHit(rays[r]);
      ASSERT_EQ(got[r].valid(), expected.valid()) << "t " << t << " ray " << r;
      EXPECT_EQ(occluded[r] != 0, cpu.anyHit(rays[r])) << "t " << t << " ray " << r;
      if (!expected.valid()) continue;
      ++hits;
      EXPECT_EQ(got[r].instance, expected.instance) << "t " << t << " ray " << r;
      EXPECT_EQ(got[r].prim, expected.prim) << "t " << t << " ray " << r;
      EXPECT_NEAR(got[r].t, expected.t, kRelativeT * std::max(1.0f, expected.t)) << "t " << t << " ray " << r;
    }
  }
  EXPECT_GT(hits, total / 4);  // the comparison saw real hits
}

TEST_F(CudaTwoLevel, HitsEqualTheCpuRuntimeAtSeveralTimes) { expectCpuHits(*scene); }

// The cloth's four instances (offsets, a loop, a keyed path) flattened into one source of
// world-space keyframes (anim::flattenObjects): one more pose, traced as any other.
TEST_F(CudaTwoLevel, AFlattenedSceneHitsAsTheCpuRuntime) {
  const tsah::TwoLevelScene flattened = tsah::buildTwoLevelScene(
      anim::flattenObjects(anim::loadSceneSources((dir / "scene.json").string()), {1}), tsah::test::smallTwoLevelOptions());
  ASSERT_EQ(flattened.instanceCount(), 4u);  // the ground's three instances and the merged one
  expectCpuHits(flattened);
}

TEST_F(CudaTwoLevel, TlasBoxesContainEveryInstanceAfterEachUpdate) {
  tsah::TwoLevelRuntime cpu(*scene);
  tsah::cuda::GpuTwoLevelRuntime gpu(*scene);
  for (const double t : scene->frameTimes) {
    cpu.update(t);
    gpu.updateAt(t);
    const std::vector<tsah::Aabb> boxes = gpu.downloadInstanceBoxes();
    const tsah::FlatBvh tlas = gpu.downloadTlas();
    const std::vector<tsah::Aabb> leafBoxes = tsah::test::tlasLeafBoxes(tlas);
    ASSERT_EQ(boxes.size(), scene->instanceCount());
    for (uint32_t i = 0; i < scene->instanceCount(); ++i) {
      // The device's world box is the CPU's (the same transform and rounding) and inside its leaf.
      EXPECT_TRUE(boxes[i].contains(cpu.instanceBoxes()[i])) << "t " << t << " instance " << i;
      EXPECT_TRUE(leafBoxes[i].contains(boxes[i])) << "t " << t << " instance " << i;
      EXPECT_TRUE(tlas.rootBoxes[0].contains(boxes[i])) << "t " << t << " instance " << i;
    }
    EXPECT_EQ(tsah::validateFlatBvh(tlas), std::nullopt) << "t " << t;
  }
}

// TLAS trees per part of the scene's time: at every frame the device refits and traces the tree of
// the frame's part (the CPU's topology, boxes holding every instance), its hits are the CPU's, and
// a shutter across a boundary blurs with the close's tree as the CPU does.
TEST_F(CudaTwoLevel, TlasTreesPerTimePartSwitchAsOnTheCpu) {
  tsah::TlasOptions parts;
  parts.trees = 4;
  const tsah::TwoLevelScene split =
      tsah::loadTwoLevelScene((dir / "scene.json").string(), {}, tsah::test::smallTwoLevelOptions(), parts);
  ASSERT_EQ(split.tlases.size(), 4u);
  tsah::TwoLevelRuntime cpu(split, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::cuda::GpuTwoLevelRuntime gpu(split);
  for (const double t : split.frameTimes) {
    cpu.update(t);
    gpu.updateAt(t);
    const tsah::FlatBvh tlas = gpu.downloadTlas();
    EXPECT_EQ(tlas.triIndex, cpu.tlas().triIndex) << "t " << t;
    EXPECT_EQ(tlas.interiorCount, tsah::flattenBvh(split.tlases[split.tlasAt(t)].bvh).interiorCount) << "t " << t;
    const std::vector<tsah::Aabb> leafBoxes = tsah::test::tlasLeafBoxes(tlas), boxes = gpu.downloadInstanceBoxes();
    for (uint32_t i = 0; i < split.instanceCount(); ++i)
      EXPECT_TRUE(leafBoxes[i].contains(boxes[i])) << "t " << t << " instance " << i;
    EXPECT_EQ(tsah::validateFlatBvh(tlas), std::nullopt) << "t " << t;
  }
  expectCpuHits(split);
  cpu.updateShutter(2.75, 3.25);  // the boundary at 3 (frame 6 of 24)
  gpu.updateShutter(2.75, 3.25);
  ASSERT_TRUE(cpu.blurred() && gpu.blurred());
  const std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(tsah::test::unionOf(cpu.instanceBoxes()), 1000, 5);
  std::vector<float> times(rays.size());
  for (std::size_t r = 0; r < rays.size(); ++r) times[r] = float(r % 11) / 10.0f;
  const std::vector<tsah::TwoLevelHit> got = gpu.closestHits(rays, times);
  for (std::size_t r = 0; r < rays.size(); ++r) {
    const tsah::TwoLevelHit expected = cpu.closestHit(rays[r], times[r]);
    ASSERT_EQ(got[r].valid(), expected.valid()) << "ray " << r;
    if (!expected.valid()) continue;
    EXPECT_EQ(got[r].instance, expected.instance) << "ray " << r;
    EXPECT_EQ(got[r].prim, expected.prim) << "ray " << r;
  }
}

// Updates both runtimes at each time and expects the same TLAS, instance boxes and hits exactly;
// check(a's timings, b's timings) sees each update.
template <class Check>
void expectSameUpdates(tsah::cuda::GpuTwoLevelRuntime& a, tsah::cuda::GpuTwoLevelRuntime& b,
                       std::span<const double> times, const Check& check) {
  for (const double t : times) {
    check(a.updateAt(t), b.updateAt(t));
    const tsah::FlatBvh ta = a.downloadTlas(), tb = b.downloadTlas();
    ASSERT_EQ(ta.nodes.size(), tb.nodes.size());
    EXPECT_EQ(std::memcmp(ta.nodes.data(), tb.nodes.data(), ta.nodes.size() * sizeof(ta.nodes[0])), 0) << "t " << t;
    EXPECT_EQ(std::memcmp(&ta.rootBoxes[0], &tb.rootBoxes[0], sizeof(tsah::Aabb)), 0) << "t " << t;
    const std::vector<tsah::Aabb> boxesA = a.downloadInstanceBoxes(), boxesB = b.downloadInstanceBoxes();
    EXPECT_EQ(std::memcmp(boxesA.data(), boxesB.data(), boxesA.size() * sizeof(tsah::Aabb)), 0) << "t " << t;
    const std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(tsah::test::unionOf(boxesA), 2000, uint32_t(t * 8) + 3);
    const std::vector<tsah::TwoLevelHit> hitsA = a.closestHits(rays), hitsB = b.closestHits(rays);
    uint32_t hits = 0;
    for (std::size_t r = 0; r < rays.size(); ++r) {
      ASSERT_EQ(hitsA[r].valid(), hitsB[r].valid()) << "t " << t << " ray " << r;
      if (!hitsA[r].valid()) continue;
      ++hits;
      EXPECT_EQ(hitsA[r].instance, hitsB[r].instance) << "t " << t << " ray " << r;
      EXPECT_EQ(hitsA[r].prim, hitsB[r].prim) << "t " << t << " ray " << r;
      EXPECT_EQ(hitsA[r].t, hitsB[r].t) << "t " << t << " ray " << r;
      EXPECT_EQ(hitsA[r].u, hitsB[r].u) << "t " << t << " ray " << r;
    }
    EXPECT_GT(hits, rays.size() / 4) << "t " << t;
  }
}

// The block refits (shared memory: blocks per part of each pose's tree, one for the TLAS) against
// the global walk: the same boxes, so the same TLAS bit for bit and the same hits exactly. Parts of
// at most 2, 5 and 16 leaves split each pose into many subtrees and a top; 512: one part.
void expectBlockRefitsEqualTheGlobalWalk(const tsah::TwoLevelScene& twoLevel, uint32_t partLeaves) {
  SCOPED_TRACE("refitPartLeaves " + std::to_string(partLeaves));
  tsah::cuda::GpuTwoLevelRuntime::Config parts;
  parts.keyedPoses = false;
  parts.refitPartLeaves = partLeaves;
  tsah::cuda::GpuTwoLevelRuntime block(twoLevel, parts);
  tsah::cuda::GpuTwoLevelRuntime::Config reference;
  reference.keyedPoses = false;
  reference.blockRefits = false;
  tsah::cuda::GpuTwoLevelRuntime global(twoLevel, reference);
  const double times[] = {0.0, 2.0, 3.25, 7.5, 12.0, 3.25};
  expectSameUpdates(block, global, times, [](const auto&, const auto&) {});
}

TEST_F(CudaTwoLevel, BlockRefitsEqualTheGlobalWalk) {
  for (const uint32_t partLeaves : {512u, 16u, 5u, 2u}) expectBlockRefitsEqualTheGlobalWalk(*scene, partLeaves);
}

// Keyed poses (the default) against refitted ones at `times`: a pose whose local time falls on a
// keyframe has the refit's tree bit for bit; between keyframes each of its child boxes and its root
// box holds the refit's. Returns how many poses fell on keyframes, between them, and how many child
// boxes were larger than the refit's (the lerp of the keyframes' boxes is looser than a refit).
struct KeyedCounts {
  uint32_t onKeys = 0, between = 0, looser = 0;
};
KeyedCounts expectKeyedPosesHoldTheRefitsBoxes(const tsah::TwoLevelScene& scene, std::span<const double> times) {
  tsah::cuda::GpuTwoLevelRuntime::Config refitted;
  refitted.keyedPoses = false;
  tsah::cuda::GpuTwoLevelRuntime keyed(scene), refit(scene, refitted);
  EXPECT_GT(keyed.keyBoxBytes(), 0u);
  EXPECT_EQ(refit.keyBoxBytes(), 0u);
  const anim::SceneSources& src = scene.scene;
  KeyedCounts counts;
  for (const double t : times) {
    keyed.updateAt(t);
    refit.updateAt(t);
    for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
      const uint32_t p = scene.instancePose[i];
      if (p == tsah::kInvalidIndex) continue;
      const anim::Animation& a = *src.sources[scene.poses[p].blas];
      const bool onKey = anim::keyframeBlend(a.times(), src.instances[i].localTime(t, a)).alpha == 0.0f;
      const tsah::FlatBvh k = keyed.downloadPoseTree(p), r = refit.downloadPoseTree(p);
      EXPECT_EQ(tsah::validateFlatBvh(k), std::nullopt) << "t " << t << " pose " << p;
      EXPECT_EQ(k.nodes.size(), r.nodes.size());
      if (k.nodes.size() != r.nodes.size()) return counts;
      if (onKey) {
        ++counts.onKeys;
        EXPECT_EQ(std::memcmp(k.nodes.data(), r.nodes.data(), k.nodes.size() * sizeof(k.nodes[0])), 0) << "t " << t;
        EXPECT_EQ(std::memcmp(&k.rootBoxes[0], &r.rootBoxes[0], sizeof(tsah::Aabb)), 0) << "t " << t;
        continue;
      }
      ++counts.between;
      EXPECT_TRUE(k.rootBoxes[0].contains(r.rootBoxes[0])) << "t " << t << " pose " << p;
      for (std::size_t n = 0; n < k.nodes.size(); ++n)
        for (int c = 0; c < 2; ++c) {
          EXPECT_TRUE(k.nodes[n].childBox(c).contains(r.nodes[n].childBox(c))) << "t " << t << " node " << n;
          counts.looser += std::memcmp(&k.nodes[n], &r.nodes[n], 12 * sizeof(float)) != 0;
        }
    }
  }
  return counts;
}

// Their hits: HitsEqualTheCpuRuntimeAtSeveralTimes.
TEST_F(CudaTwoLevel, KeyedPosesHoldTheRefitsBoxes) {
  const KeyedCounts counts = expectKeyedPosesHoldTheRefitsBoxes(*scene, std::vector<double>{0.0, 2.0, 3.25, 7.5, 10.0, 12.0});
  EXPECT_GT(counts.onKeys, 0u);
  EXPECT_GT(counts.between, 0u);
  EXPECT_GT(counts.looser, 0u);
}

// Sources with static vertices: a wave whose first half holds still (its keyframes store the
// moving half only) and one whose keyframes are all the same (animated, no vertex moving). The keyed
// update reads a static vertex at its rest position.
TEST(CudaTwoLevelKeyed, SourcesWithStaticVerticesHitAsTheCpuRuntime) {
  REQUIRE_GPU();
  const fs::path dir = tsah::test::scratchDir();
  const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 300, 9, 3);
  const std::vector<uint32_t> indices(wave.indices().begin(), wave.indices().end());
  const std::vector<double> times(wave.times().begin(), wave.times().end());
  const std::vector<float> first = wave.keyframe(0);
  std::vector<float> half, held;
  for (uint32_t k = 0; k < wave.keyframeCount(); ++k) {
    std::vector<float> f = wave.keyframe(k);
    std::copy_n(first.begin(), 3 * std::size_t(wave.vertexCount() / 2), f.begin());
    half.insert(half.end(), f.begin(), f.end());
    held.insert(held.end(), first.begin(), first.end());
  }
  const anim::Animation halfMoving(indices, wave.vertexCount(), half, times, "half");
  const anim::Animation still(indices, wave.vertexCount(), held, times, "held");
  ASSERT_GT(halfMoving.movingVertexCount(), 0u);
  ASSERT_LT(halfMoving.movingVertexCount(), wave.vertexCount());
  ASSERT_EQ(still.movingVertexCount(), 0u);
  anim::saveTanim(halfMoving, (dir / "half.tanim").string());
  anim::saveTanim(still, (dir / "held.tanim").string());
  tsah::test::writeText(dir / "s.json", R"({"fps": 2, "objects": [
    {"file": "half.tanim", "instances": [{}, {"offset": 0.75, "transform": {"translate": [0, 0, 3]}},
                                         {"offset": 2.25, "transform": {"translate": [3, 0, 0], "rotate": [0, 30, 0]}}]},
    {"file": "held.tanim", "instances": [{"transform": {"translate": [0, 2, 0]}},
                                         {"offset": 1.25, "transform": {"translate": [0, -2, 0], "scale": [1, 1, -1]}}]}]})");
  const tsah::TwoLevelScene scene = tsah::loadTwoLevelScene((dir / "s.json").string(), {}, tsah::test::smallTwoLevelOptions());
  ASSERT_EQ(scene.poses.size(), 5u);
  const KeyedCounts counts = expectKeyedPosesHoldTheRefitsBoxes(scene, std::vector<double>{0.0, 1.0, 2.6, 5.3});
  EXPECT_GT(counts.onKeys, 0u);
  EXPECT_GT(counts.between, 0u);
  expectCpuHits(scene);
}

// Config::phaseTimings = false times the update by its start and end only (the whole update in
// blasMs, no upload or TLAS phase) and updates as the timed runtime does.
TEST_F(CudaTwoLevel, UpdatesWithoutPhaseTimingsAreTheSame) {
  tsah::cuda::GpuTwoLevelRuntime::Config quiet;
  quiet.phaseTimings = false;
  tsah::cuda::GpuTwoLevelRuntime timed(*scene), untimed(*scene, quiet);
  const double times[] = {0.0, 2.0, 3.25, 7.5, 7.5};
  expectSameUpdates(timed, untimed, times, [](const tsah::cuda::TwoLevelUpdateTimings& a,
                                              const tsah::cuda::TwoLevelUpdateTimings& b) {
    EXPECT_EQ(b.uploadMs, 0.0);
    EXPECT_EQ(b.tlasMs, 0.0);
    EXPECT_GT(b.blasMs, 0.0);
    EXPECT_GT(a.tlasMs, 0.0);  // the timed runtime's phases
    EXPECT_EQ(a.blasRefits, b.blasRefits);
    EXPECT_EQ(a.tlasNodes, b.tlasNodes);
  });
}

TEST_F(CudaTwoLevel, AFrameWithOnlyRigidMotionRefitsNoBlas) {
  tsah::cuda::GpuTwoLevelRuntime gpu(*scene);
  EXPECT_EQ(gpu.blasRefits(), 1u + 3u);  // the static BLAS once, the three poses at the first frame
  const tsah::cuda::TwoLevelUpdateTimings moving = gpu.updateAt(2.0);
  EXPECT_EQ(moving.blasRefits, 3u);
  EXPECT_EQ(moving.instances, scene->instanceCount());
  EXPECT_EQ(moving.tlasNodes, tsah::flattenBvh(scene->tlases[scene->tlasAt(2.0)].bvh).interiorCount);
  EXPECT_EQ(moving.tlasRebuildMs, 0.0);  // the refit rebuilds nothing
  const tsah::cuda::TwoLevelUpdateTimings same = gpu.updateAt(2.0);
  EXPECT_EQ(same.blasRefits, 0u);
  EXPECT_EQ(gpu.blasRefits(), 1u + 3u + 3u);
}

TEST_F(CudaTwoLevel, RebuiltTlasTracesLikeTheRefit) {
  const double times[] = {0.0, 2.0, 2.0, 3.25, 7.5, 12.0};
  expectRebuiltTlasTracesLikeTheRefit(*scene, times, 11);
}

TEST_F(CudaTwoLevel, RebuiltTlasOfACrowdTracesLikeTheRefit) {
  const tsah::TwoLevelScene crowd =
      tsah::loadTwoLevelScene(tsah::test::writeCrowdScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  ASSERT_EQ(crowd.instanceCount(), 64u);
  const double times[] = {0.0, 1.5, 1.5, 6.0, 9.75, 12.0};
  expectRebuiltTlasTracesLikeTheRefit(crowd, times, 101);
}

// Only the refit uploads the T-SAH TLAS, but every update checks it against the instances: a TLAS
// over one instance too few is refused (tsah::DataError naming the TLAS) whatever Config::tlas is.
TEST_F(CudaTwoLevel, EveryTlasUpdateRefusesATlasMissingAnInstance) {
  tsah::TwoLevelScene broken = *scene;
  std::vector<tsah::Aabb> boxes;
  for (uint32_t i = 0; i + 1 < broken.instanceCount(); ++i)
    boxes.push_back(tsah::instanceWorldBox(broken.scene, i, broken.frameTimes.front()));
  ASSERT_FALSE(boxes.empty());
  broken.tlases.resize(1);
  broken.tlases[0].range = {broken.scene.start, broken.scene.end};
  broken.tlases[0].bvh = tsah::rebuildTlas(boxes, broken.objective);
  using tsah::cuda::TlasUpdate;
  for (const TlasUpdate update : {TlasUpdate::Refit, TlasUpdate::Lbvh, TlasUpdate::HlbvhSah}) {
    SCOPED_TRACE(tsah::cuda::tlasUpdateName(update));
    tsah::cuda::GpuTwoLevelRuntime::Config config;
    config.tlas = update;
    try {
      tsah::cuda::GpuTwoLevelRuntime gpu(broken, config);
      ADD_FAILURE() << "a TLAS of " << boxes.size() << " instances accepted for " << broken.instanceCount();
    } catch (const tsah::DataError& e) {
      EXPECT_NE(std::string(e.what()).find("GPU two-level runtime: TLAS 0:"), std::string::npos) << e.what();
    }
  }
}

TEST(CudaTwoLevelNames, TlasUpdateNamesRoundTrip) {
  for (const auto u : {tsah::cuda::TlasUpdate::Refit, tsah::cuda::TlasUpdate::Lbvh, tsah::cuda::TlasUpdate::HlbvhSah})
    EXPECT_EQ(tsah::cuda::parseTlasUpdate(tsah::cuda::tlasUpdateName(u)), u);
  EXPECT_STREQ(tsah::cuda::tlasUpdateName(tsah::cuda::TlasUpdate::HlbvhSah), "hlbvh-sah");
  EXPECT_THROW(tsah::cuda::parseTlasUpdate("sah"), tsah::ConfigError);
}

// The GPU runtime's closest hits of rays through the instances' boxes against the CPU runtime's,
// both updated to time t: the same instance and triangle.
void expectClosestHitsAsTheCpu(tsah::cuda::GpuTwoLevelRuntime& gpu, const tsah::TwoLevelRuntime& cpu, double t) {
  const std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(tsah::test::unionOf(cpu.instanceBoxes()), 500, 3);
  const std::vector<tsah::TwoLevelHit> got = gpu.closestHits(rays);
  for (std::size_t r = 0; r < rays.size(); ++r) {
    const tsah::TwoLevelHit expected = cpu.closestHit(rays[r]);
    ASSERT_EQ(got[r].valid(), expected.valid()) << "t " << t << " ray " << r;
    if (expected.valid()) {
      EXPECT_EQ(got[r].instance, expected.instance) << "t " << t << " ray " << r;
      EXPECT_EQ(got[r].prim, expected.prim) << "t " << t << " ray " << r;
    }
  }
}

TEST(CudaTwoLevelRigid, OnlyPathsAndHeldPosesRefitNothing) {
  REQUIRE_GPU();
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeRigidPathScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  tsah::TwoLevelRuntime cpu(s);
  tsah::cuda::GpuTwoLevelRuntime gpu(s);
  EXPECT_EQ(gpu.updateAt(3.0).blasRefits, 2u);
  EXPECT_EQ(gpu.updateAt(5.0).blasRefits, 2u);  // both poses reach their last frame (local time 4)
  for (const double t : {6.0, 6.25, 7.0, 8.0}) {  // and hold it while the path moves on
    EXPECT_EQ(gpu.updateAt(t).blasRefits, 0u) << "t " << t;
    cpu.update(t);
    expectClosestHitsAsTheCpu(gpu, cpu, t);  // the rigid graph still moved the instances along the path
  }
}

// From t = 4 the pose without an offset holds its last frame while the offset one moves on until
// t = 5: only the moving pose is updated (as on the CPU), and the held one keeps its last frame's
// positions, boxes and triangles (the hits equal the CPU runtime's, which refits only what moved).
// Each way the GPU updates a pose: keyed, the block refit and the global walk.
TEST(CudaTwoLevelRigid, AHeldPoseIsLeftAsItIsWhileAnotherMoves) {
  REQUIRE_GPU();
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeRigidPathScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  for (const int way : {0, 1, 2}) {
    SCOPED_TRACE(way == 0 ? "keyed" : way == 1 ? "block refit" : "global walk");
    tsah::cuda::GpuTwoLevelRuntime::Config config;
    config.keyedPoses = way == 0;
    config.blockRefits = way != 2;
    tsah::TwoLevelRuntime cpu(s);
    tsah::cuda::GpuTwoLevelRuntime gpu(s, config);
    gpu.updateAt(3.0);
    cpu.update(3.0);
    const std::pair<double, uint32_t> steps[] = {{4.25, 2u}, {4.5, 1u}, {4.75, 1u}, {5.0, 1u}, {5.5, 0u}};
    for (const auto& [t, refits] : steps) {
      EXPECT_EQ(gpu.updateAt(t).blasRefits, refits) << "t " << t;
      cpu.update(t);
      EXPECT_EQ(cpu.lastUpdateBlasRefits(), refits) << "t " << t;
      expectClosestHitsAsTheCpu(gpu, cpu, t);
    }
  }
}

}  // namespace

#endif  // TSAH_HAVE_CUDA
