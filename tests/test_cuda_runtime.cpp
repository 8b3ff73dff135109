// The CUDA runtime against the CPU runtime: interpolated positions, refitted boxes and Woop
// triangles bit for bit; closest and any hits on random rays (same triangle or a tie at the same
// distance); rendered images; rebuilt LBVH / HLBVH-SAH trees valid, collapsed as the CPU collapser
// would, and tracing like the refitted tree. Every test that needs a GPU skips without one.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <type_traits>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/moving_parts.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

using tsah::Vec3;
namespace tc = tsah::cuda;

using tsah::test::generatedAnimation;

// Sweep SAH on the first keyframe, collapsed to leaves of up to maxLeaf triangles.
tsah::FlatBvh sahTree(const anim::Animation& a, uint32_t maxLeaf) {
  tsah::Bvh bvh = tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0));
  if (maxLeaf > 1) {
    tsah::LeafCollapser::Config c;
    c.maxLeafSize = maxLeaf;
    bvh = tsah::LeafCollapser(c).collapse(bvh);
  }
  return tsah::flattenBvh(bvh);
}

tsah::CpuRuntime cpuRuntime(const tsah::FlatBvh& tree, const anim::Animation& a) {
  return tsah::CpuRuntime(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
}

Vec3 randomUnit(std::mt19937& rng) {
  std::normal_distribution<float> g;
  return tsah::normalize(Vec3{g(rng), g(rng), g(rng)});
}

// Rays of test_traversal.cpp's kinds: towards triangles from outside, and from inside in any
// direction, some with tmin > 0 or a short tmax.
std::vector<tsah::Ray> randomRays(const tsah::BvhView& v, const tsah::Aabb& b, uint32_t triangles, uint32_t count,
                                  uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> ux(b.lo.x, b.hi.x), uy(b.lo.y, b.hi.y), uz(b.lo.z, b.hi.z), u01(0, 1);
  const float diag = std::sqrt(tsah::dot(b.extent(), b.extent()));
  std::vector<tsah::Ray> rays(count);
  for (uint32_t i = 0; i < count; ++i) {
    tsah::Ray& ray = rays[i];
    const uint32_t kind = i % 3;
    if (kind == 0) {
      const uint32_t* tri = v.indices + 3 * (rng() % triangles);
      const Vec3 target = (v.vertex(tri[0]) + v.vertex(tri[1]) + v.vertex(tri[2])) * (1.0f / 3.0f) +
                          randomUnit(rng) * (0.01f * diag);
      ray.org = b.center() + randomUnit(rng) * diag;
      ray.dir = target - ray.org;
    } else {
      ray.org = {ux(rng), uy(rng), uz(rng)};
      ray.dir = randomUnit(rng) * (0.1f + 3.0f * u01(rng));
    }
    ray.tmin = kind == 2 ? 0.01f * u01(rng) : 0.0f;
    ray.tmax = (i % 4 == 0) ? u01(rng) * 2.0f : 3.4e38f;
  }
  return rays;
}

// GPU hits against the CPU traversal of `cpu` (the same geometry, any tree): the same answer to
// "is there a hit", distances within a relative 1e-5, the same triangle unless two triangles lie at
// that distance (a shared edge or vertex); any-hit agrees with closest-hit.
void expectSameHits(tc::GpuRuntime& gpu, const tsah::CpuRuntime& cpu, uint32_t count, uint32_t seed) {
  const tsah::BvhView v = cpu.view();
  const auto rays = randomRays(v, cpu.bounds(), cpu.triangleCount(), count, seed);
  tsah::RayPassStats stats;
  const std::vector<tsah::Hit> got = gpu.closestHits(rays, &stats);
  const std::vector<uint8_t> occluded = gpu.anyHits(rays);
  ASSERT_EQ(got.size(), rays.size());
  EXPECT_EQ(stats.rays, rays.size());
  EXPECT_GT(stats.ms, 0.0);
  uint32_t hits = 0, ties = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const tsah::Hit expect = tsah::closestHit(v, rays[i]);
    ASSERT_EQ(expect.valid(), got[i].valid()) << "ray " << i;
    ASSERT_EQ(expect.valid() ? 1 : 0, occluded[i]) << "any hit, ray " << i;
    if (!expect.valid()) continue;
    ++hits;
    ASSERT_NEAR(expect.t, got[i].t, 1e-5f * std::abs(expect.t)) << "ray " << i;
    if (expect.tri != got[i].tri) {
      ++ties;
      continue;
    }
    ASSERT_NEAR(expect.u, got[i].u, 1e-4f) << "ray " << i;
    ASSERT_NEAR(expect.v, got[i].v, 1e-4f) << "ray " << i;
  }
  EXPECT_GT(hits, count / 25) << "the rays must actually hit something";
  EXPECT_LE(ties, count / 100) << "ties must be rare";
}

TEST(CudaDevice, AvailabilityNeverThrows) {
  bool available = false;
  EXPECT_NO_THROW(available = tc::deviceAvailable());
  if (available) {
    const tc::DeviceInfo info = tc::describeDevice(0);
    EXPECT_FALSE(info.name.empty());
    EXPECT_GT(info.multiprocessors, 0);
  }
}

TEST(CudaCheck, NamesTheCallTheFileAndTheError) {
  try {
    CUDA_CHECK(cudaErrorInvalidValue);
    FAIL() << "CUDA_CHECK did not throw";
  } catch (const tc::CudaError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.code(), cudaErrorInvalidValue);
    EXPECT_NE(what.find("cudaErrorInvalidValue"), std::string::npos) << what;
    EXPECT_NE(what.find("test_cuda_runtime.cpp"), std::string::npos) << what;
    EXPECT_NE(what.find("invalid argument"), std::string::npos) << what;
  }
  EXPECT_NO_THROW(CUDA_CHECK(cudaSuccess));
  // A device error is a failure of the work, not a mistake of the caller.
  static_assert(std::is_base_of_v<tsah::Failure, tc::CudaError>);
  EXPECT_THROW(CUDA_CHECK(cudaErrorInvalidValue), tsah::Failure);
}

TEST(CudaRuntime, RejectsATreeOfAnotherAnimationWithoutTouchingTheDevice) {
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 800, 3);
  const auto b = generatedAnimation(anim::GeneratorKind::Explode, 1500, 3);
  EXPECT_THROW(tc::GpuRuntime(sahTree(b, 8), a), tsah::DataError);
  EXPECT_THROW(tc::parseRebuildMethod("octree"), tsah::ConfigError);
  EXPECT_EQ(tc::parseRebuildMethod("hlbvh-sah"), tc::RebuildMethod::HlbvhSah);
  EXPECT_STREQ(tc::rebuildMethodName(tc::RebuildMethod::Lbvh), "lbvh");
}

TEST(CudaBuffer, RoundTripAndMove) {
  REQUIRE_GPU();
  std::vector<uint32_t> host(1000);
  for (uint32_t i = 0; i < host.size(); ++i) host[i] = i * 2654435761u;
  tc::DeviceBuffer<uint32_t> a{std::span<const uint32_t>(host)};
  EXPECT_EQ(a.size(), host.size());
  tc::DeviceBuffer<uint32_t> b = std::move(a);
  EXPECT_EQ(a.size(), 0u);
  EXPECT_EQ(a.data(), nullptr);
  EXPECT_EQ(b.download(), host);
  EXPECT_THROW(b.upload(std::vector<uint32_t>(1001)), tsah::Error);
  b.resize(10);
  EXPECT_EQ(b.size(), 10u);
}

TEST(CudaRuntime, RefusesToTraceBeforeAnUpdate) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 800, 3);
  tc::GpuRuntime gpu(sahTree(a, 4), a);
  const std::vector<tsah::Ray> rays(4, tsah::Ray{{0, 0, 0}, 0, {0, 0, 1}, 1});
  EXPECT_THROW(gpu.closestHits(rays), tsah::Error);
  gpu.updateAt(a.startTime());
  EXPECT_NO_THROW(gpu.closestHits(rays));
  EXPECT_THROW(gpu.downloadRebuiltTree(), tsah::Error);
}

// Interpolation, refit and Woop equal the CPU runtime's, bit for bit, at times before, between,
// on and after the keyframes; for a tree of single-triangle leaves and one of collapsed leaves.
TEST(CudaRuntime, UpdateEqualsTheCpuRuntimeExactly) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 6000, 9);
  for (uint32_t maxLeaf : {1u, 8u}) {
    SCOPED_TRACE("max leaf " + std::to_string(maxLeaf));
    const tsah::FlatBvh tree = sahTree(a, maxLeaf);
    tsah::CpuRuntime cpu = cpuRuntime(tree, a);
    // Both ways of launching the update: CUDA graphs for single-triangle leaves.
    tc::GpuRuntime gpu(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, maxLeaf == 1));
    const double t0 = a.startTime(), t1 = a.endTime();
    for (double t : {t0 - 1.0, t0, t0 + 0.37 * (t1 - t0), a.times()[3], 0.999 * t1, t1, t1 + 5.0}) {
      const std::vector<float> pos = a.positionsAt(t);
      cpu.update(pos);
      const tc::UpdateTimings timings = gpu.updateAt(t);
      EXPECT_GE(timings.totalMs(), 0.0);
      const std::vector<float> gpuPos = gpu.downloadPositions();
      ASSERT_EQ(gpuPos.size(), pos.size());
      ASSERT_EQ(0, std::memcmp(gpuPos.data(), pos.data(), pos.size() * sizeof(float))) << "positions at t=" << t;

      const tsah::FlatBvh got = gpu.downloadTree();
      const tsah::FlatBvh& expect = cpu.tree();
      ASSERT_EQ(got.interiorCount, expect.interiorCount);
      ASSERT_EQ(got.triIndex, expect.triIndex);
      ASSERT_EQ(0, std::memcmp(&got.rootBoxes[0], &expect.rootBoxes[0], sizeof(tsah::Aabb))) << "root, t=" << t;
      for (uint32_t i = 0; i < expect.interiorCount; ++i)
        ASSERT_EQ(0, std::memcmp(&got.nodes[i], &expect.nodes[i], sizeof(tsah::GpuBvhNode))) << "node " << i;
      EXPECT_FALSE(tsah::validateFlatBvh(got).has_value());

      const std::vector<tsah::WoopTriangle> woop = gpu.downloadWoop();
      ASSERT_EQ(woop.size(), cpu.woop().size());
      ASSERT_EQ(0, std::memcmp(woop.data(), cpu.woop().data(), woop.size() * sizeof(tsah::WoopTriangle)))
          << "Woop triangles at t=" << t;
    }
    // Host positions take the same path.
    const std::vector<float> pos = a.positionsAt(0.5 * (t0 + t1));
    cpu.update(pos);
    gpu.update(pos);
    ASSERT_EQ(0, std::memcmp(&gpu.downloadTree().rootBoxes[0], &cpu.tree().rootBoxes[0], sizeof(tsah::Aabb)));
    EXPECT_THROW(gpu.update(std::vector<float>(pos.size() - 3)), tsah::Error);
  }
}

// A scene with a big static part: a static environment (a generated mesh at rest) next to a moving
// one, so the device keys only the moving vertices and must leave the static ones in place. The
// update equals the CPU runtime's bit for bit, also after host positions overwrote the static part.
TEST(CudaRuntime, UpdateOfAMostlyStaticSceneEqualsTheCpuRuntime) {
  REQUIRE_GPU();
  const anim::Animation a = tsah::test::mostlyStaticAnimation();
  ASSERT_FALSE(a.allMoving());
  ASSERT_LT(a.movingVertexCount(), a.vertexCount() / 2);
  const tsah::FlatBvh tree = sahTree(a, 8);
  tsah::CpuRuntime cpu = cpuRuntime(tree, a);
  for (bool graphs : {true, false}) {
    tc::GpuRuntime gpu(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
    const double t0 = a.startTime(), t1 = a.endTime();
    for (double t : {t0, t0 + 0.37 * (t1 - t0), a.times()[2], t1 + 1.0, t0 + 0.61 * (t1 - t0)}) {
      // Host positions with a displaced static part first: updateAt must put the rest back.
      std::vector<float> junk = a.positionsAt(t1);
      for (float& x : junk) x += 1.0f;
      gpu.update(junk);
      const std::vector<float> expect = a.positionsAt(t);
      cpu.update(expect);
      gpu.updateAt(t);
      const std::vector<float> got = gpu.downloadPositions();
      ASSERT_EQ(0, std::memcmp(got.data(), expect.data(), expect.size() * sizeof(float))) << "positions at t=" << t;
      const std::vector<tsah::WoopTriangle> woop = gpu.downloadWoop();
      ASSERT_EQ(0, std::memcmp(woop.data(), cpu.woop().data(), woop.size() * sizeof(tsah::WoopTriangle)))
          << "Woop triangles at t=" << t;
      ASSERT_EQ(0, std::memcmp(&gpu.downloadTree().rootBoxes[0], &cpu.tree().rootBoxes[0], sizeof(tsah::Aabb)));
    }
  }
}

// Static subtrees (moving_parts.hpp): once a full update put them in place, updateAt refits only the
// moving leaves and recomputes only the moving slots' Woop triangles (counted by slotsUpdated), and
// every node box, the root box and every Woop triangle still equal the CPU runtime's full refit bit
// for bit. Host positions and rebuilds, which may change the static part or the Woop buffer, make
// the next update a full one again.
TEST(CudaRuntime, StaticSubtreesAreSkippedAndTheTreeEqualsAFullRefit) {
  REQUIRE_GPU();
  const anim::Animation a = tsah::test::mostlyStaticAnimation();
  const tsah::FlatBvh tree = sahTree(a, 8);
  const tsah::MovingParts parts = tsah::findMovingParts(tree, a.indices(), a.movingVertices(), a.vertexCount());
  ASSERT_GT(parts.movingSlots, 0u);
  ASSERT_LT(parts.movingSlots, a.triangleCount() / 2);
  tsah::CpuRuntime cpu = cpuRuntime(tree, a);
  const double t0 = a.startTime(), t1 = a.endTime();
  for (bool graphs : {true, false}) {
    SCOPED_TRACE(graphs ? "graphs" : "launches");
    tc::GpuRuntime gpu(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
    const auto updateAndCompare = [&](double t, uint32_t slotsUpdated) {
      SCOPED_TRACE("t = " + std::to_string(t));
      cpu.update(a.positionsAt(t));
      EXPECT_EQ(gpu.updateAt(t).slotsUpdated, slotsUpdated);
      const tsah::FlatBvh got = gpu.downloadTree();
      ASSERT_EQ(0, std::memcmp(&got.rootBoxes[0], &cpu.tree().rootBoxes[0], sizeof(tsah::Aabb)));
      for (uint32_t i = 0; i < tree.interiorCount; ++i)
        ASSERT_EQ(0, std::memcmp(&got.nodes[i], &cpu.tree().nodes[i], sizeof(tsah::GpuBvhNode))) << "node " << i;
      const std::vector<tsah::WoopTriangle> woop = gpu.downloadWoop();
      ASSERT_EQ(0, std::memcmp(woop.data(), cpu.woop().data(), woop.size() * sizeof(tsah::WoopTriangle)));
    };
    const uint32_t all = a.triangleCount(), moving = parts.movingSlots;
    updateAndCompare(t0, all);  // the first update puts the static subtrees in place
    for (double f : {0.37, 0.9, 0.1}) updateAndCompare(t0 + f * (t1 - t0), moving);
    updateAndCompare(a.times()[2], moving);
    gpu.update(a.positionsAt(t1));  // host positions: the static part may have moved
    updateAndCompare(t0 + 0.5 * (t1 - t0), all);
    updateAndCompare(t1, moving);
    gpu.rebuildAt(t0);  // writes its own Woop triangles
    updateAndCompare(t0 + 0.25 * (t1 - t0), all);
    updateAndCompare(t0 + 0.75 * (t1 - t0), moving);
  }
  // Every vertex moving: every update refits everything.
  const auto everything = generatedAnimation(anim::GeneratorKind::Explode, 2000, 4);
  tc::GpuRuntime gpu(sahTree(everything, 8), everything, tsah::test::gpuConfig(tsah::Layout::Bvh2, true));
  for (double t : {everything.startTime(), everything.endTime()})
    EXPECT_EQ(gpu.updateAt(t).slotsUpdated, everything.triangleCount());
}

TEST(CudaRuntime, HitsEqualTheCpuTraversal) {
  REQUIRE_GPU();
  uint32_t seed = 11;
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave, anim::GeneratorKind::Swap}) {
    const auto a = generatedAnimation(kind, 3000, 6, seed);
    const tsah::FlatBvh tree = sahTree(a, 8);
    tsah::CpuRuntime cpu = cpuRuntime(tree, a);
    for (bool persistent : {true, false}) {
      tc::GpuRuntime gpu(tree, a, {0, persistent});
      for (double t : {a.startTime(), 0.5 * (a.startTime() + a.endTime()), a.endTime()}) {
        cpu.update(a.positionsAt(t));
        gpu.updateAt(t);
        expectSameHits(gpu, cpu, 6000, ++seed);
      }
    }
  }
}

// A tree that is a single leaf (no interior node) refits, traces and renders too.
TEST(CudaRuntime, SingleLeafTree) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 6, 4);
  ASSERT_LE(a.triangleCount(), 16u);
  const tsah::FlatBvh tree = tsah::test::singleLeafTree(a);
  ASSERT_EQ(tree.interiorCount, 0u);
  tsah::CpuRuntime cpu = cpuRuntime(tree, a);
  tc::GpuRuntime gpu(tree, a);
  const double t = 0.3 * a.endTime();
  cpu.update(a.positionsAt(t));
  gpu.updateAt(t);
  ASSERT_EQ(0, std::memcmp(&gpu.downloadTree().rootBoxes[0], &cpu.tree().rootBoxes[0], sizeof(tsah::Aabb)));
  expectSameHits(gpu, cpu, 3000, 5);
}

// The whole frame: same ray counts and, pixel by pixel, the same image up to the last bit of the
// device's sin/cos/pow/exp.
TEST(CudaRender, ImageMatchesTheCpuRenderer) {
  REQUIRE_GPU();
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 4000, 5);
  const tsah::FlatBvh tree = sahTree(a, 8);
  tsah::CpuRuntime cpu = cpuRuntime(tree, a);
  tc::GpuRuntime gpu(tree, a);
  auto [bounds, settings, camera] = tsah::test::renderView(a);  // 203 wide: not a multiple of the 8 x 4 tiles
  const tsah::SceneLighting lighting = tsah::fitLighting(bounds, camera);
  for (uint32_t frame : {0u, 3u}) {
    settings.frame = frame;
    const double t = a.uniformTimes(5)[frame];
    cpu.update(a.positionsAt(t));
    gpu.updateAt(t);
    tsah::Image cpuImage, gpuImage;
    const tsah::RenderStats expect = tsah::renderFrame(cpu, camera, lighting, settings, cpuImage);
    tc::GpuRenderTimings timings;
    const tsah::RenderStats got = tc::renderFrameGpu(gpu, camera, lighting, settings, gpuImage, &timings);
    ASSERT_EQ(gpuImage.width, settings.width);
    ASSERT_EQ(gpuImage.height, settings.height);
    tsah::test::expectRayCountsClose(got, expect);
    EXPECT_GT(got.ao.rays, 0u);
    EXPECT_GT(got.shadow.rays, 0u);
    EXPECT_GT(timings.totalMs, 0.0);
    tsah::test::expectImagesClose(cpuImage, gpuImage, "frame " + std::to_string(frame));
  }
  // Without an image: the same statistics, nothing downloaded.
  const tsah::RenderStats none = tc::renderFrameGpu(gpu, camera, lighting, settings, nullptr);
  EXPECT_EQ(none.primary.rays, uint64_t(settings.width) * settings.height);
  settings.width = 0;
  tsah::Image image;
  EXPECT_THROW(tc::renderFrameGpu(gpu, camera, lighting, settings, image), tsah::Error);
}

// --- Rebuilds ---------------------------------------------------------------------------------

tsah::PrimitiveBoxes boxesAt(const anim::Animation& a, double t) {
  const std::vector<float> pos = a.positionsAt(t);
  return tsah::triangleBoxes(a.indices(), pos, 1);
}

uint32_t largestLeaf(const tsah::Bvh& bvh) {
  uint32_t m = 0;
  for (const auto& n : bvh.nodes) m = std::max(m, n.primCount);
  return m;
}

void checkRebuild(const anim::Animation& a, tc::RebuildMethod method, uint32_t seed, bool graphs = true) {
  SCOPED_TRACE(tc::rebuildMethodName(method));
  const tsah::FlatBvh tree = sahTree(a, 8);
  tc::GpuRuntime gpu(tree, a, tsah::test::gpuConfig(tsah::Layout::Bvh2, graphs));
  tsah::CpuRuntime cpu = cpuRuntime(tree, a);
  for (double t : {a.startTime(), 0.61 * a.endTime()}) {
    const tsah::PrimitiveBoxes prims = boxesAt(a, t);

    // Bare: one triangle per leaf.
    tc::RebuildOptions bare;
    bare.method = method;
    bare.collapse = false;
    const tc::RebuildTimings bareTimings = gpu.rebuildAt(t, bare);
    const tsah::Bvh bareTree = gpu.downloadRebuiltTree();
    ASSERT_FALSE(tsah::validate(bareTree, &prims).has_value()) << *tsah::validate(bareTree, &prims);
    EXPECT_EQ(largestLeaf(bareTree), 1u);
    EXPECT_EQ(bareTree.leafCount(), a.triangleCount());
    EXPECT_EQ(bareTimings.leaves, bareTree.leafCount());
    EXPECT_EQ(bareTimings.depth, bareTree.depth());
    if (method == tc::RebuildMethod::HlbvhSah) {
      EXPECT_GE(bareTimings.clusters, 1u);
      EXPECT_LE(bareTimings.clusters, std::min(a.triangleCount(), 32768u));
    }

    // Collapsed: valid, at most 8 per leaf, and the same collapse as LeafCollapser on the bare tree
    // (float on the GPU, double on the CPU: equal costs up to rounding).
    tc::RebuildOptions full;
    full.method = method;
    const tc::RebuildTimings timings = gpu.rebuildAt(t, full);
    const tsah::Bvh collapsed = gpu.downloadRebuiltTree();
    ASSERT_FALSE(tsah::validate(collapsed, &prims).has_value()) << *tsah::validate(collapsed, &prims);
    EXPECT_LE(largestLeaf(collapsed), 8u);
    EXPECT_EQ(timings.leaves, collapsed.leafCount());
    EXPECT_EQ(timings.interiorNodes + 1, collapsed.leafCount());
    EXPECT_EQ(timings.depth, collapsed.depth());
    EXPECT_GT(timings.totalMs(), 0.0);
    tsah::LeafCollapser::Config lc;
    lc.maxLeafSize = 8;
    const tsah::Bvh reference = tsah::LeafCollapser(lc).collapse(bareTree);
    const double cpuCost = tsah::frameCost(reference, 0), gpuCost = tsah::frameCost(collapsed, 0);
    EXPECT_NEAR(gpuCost, cpuCost, 1e-4 * cpuCost);
    EXPECT_LT(gpuCost, tsah::frameCost(bareTree, 0));
    EXPECT_NEAR(double(collapsed.leafCount()), double(reference.leafCount()), 0.002 * reference.leafCount() + 2);

    // It traces like the refit tree (same geometry, other tree).
    const std::vector<float> pos = a.positionsAt(t);
    cpu.update(pos);
    expectSameHits(gpu, cpu, 4000, seed++);
    // Leaves cover the slots in depth-first order, so the canonical form keeps the device's slot
    // order, and the device's Woop triangles are the CPU runtime's for that tree, bit for bit.
    const tsah::FlatBvh flat = gpu.downloadTree();
    ASSERT_FALSE(tsah::validateFlatBvh(flat).has_value());
    tsah::CpuRuntime rebuiltOnCpu(flat, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
    rebuiltOnCpu.update(pos);
    const std::vector<tsah::WoopTriangle> woop = gpu.downloadWoop();
    ASSERT_EQ(woop.size(), rebuiltOnCpu.woop().size());
    ASSERT_EQ(0, std::memcmp(woop.data(), rebuiltOnCpu.woop().data(), woop.size() * sizeof(tsah::WoopTriangle)));
    expectSameHits(gpu, rebuiltOnCpu, 2000, seed++);
  }
  // Back to the refit tree.
  gpu.updateAt(a.startTime());
  EXPECT_FALSE(gpu.tracingRebuiltTree());
}

// checkRebuild on 5000 triangles of every generator, seeds seed + 10, + 20, + 30; the wave without
// CUDA graphs.
void checkRebuildOnEveryGenerator(tc::RebuildMethod method, uint32_t seed) {
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave, anim::GeneratorKind::Swap}) {
    seed += 10;
    checkRebuild(generatedAnimation(kind, 5000, 4, seed), method, seed, kind != anim::GeneratorKind::Wave);
  }
}

TEST(CudaRebuild, LbvhTreesAreValidCollapsedAndTraceLikeTheRefitTree) {
  REQUIRE_GPU();
  checkRebuildOnEveryGenerator(tc::RebuildMethod::Lbvh, 100);
}

TEST(CudaRebuild, HlbvhSahTreesAreValidCollapsedAndTraceLikeTheRefitTree) {
  REQUIRE_GPU();
  checkRebuildOnEveryGenerator(tc::RebuildMethod::HlbvhSah, 200);
  // Many clusters (the persistent cluster-tree builder gets real work).
  checkRebuild(generatedAnimation(anim::GeneratorKind::Explode, 60000, 2, 7), tc::RebuildMethod::HlbvhSah, 300);
}

// Degenerate inputs: one triangle, two, and many triangles with the same centroid (equal Morton
// codes: the radix tree falls back to the index bits).
TEST(CudaRebuild, TinyAndDuplicateInputs) {
  REQUIRE_GPU();
  auto build = [](std::vector<float> positions, std::vector<uint32_t> indices) {
    const uint32_t vertices = uint32_t(positions.size() / 3);
    std::vector<float> two = positions;
    for (std::size_t i = 0; i < positions.size(); ++i) two.push_back(positions[i] + 0.25f);
    return anim::Animation(std::move(indices), vertices, std::move(two), {0.0, 1.0});
  };
  const std::vector<float> tri{0, 0, 0, 1, 0, 0, 0, 1, 0};
  std::vector<anim::Animation> cases;
  cases.push_back(build(tri, {0, 1, 2}));
  cases.push_back(build({0, 0, 0, 1, 0, 0, 0, 1, 0, 3, 3, 3, 4, 3, 3, 3, 4, 3}, {0, 1, 2, 3, 4, 5}));
  {
    std::vector<float> p;
    std::vector<uint32_t> idx;
    for (uint32_t i = 0; i < 300; ++i) {  // the same triangle 300 times, rotated vertex order
      for (float v : tri) p.push_back(v);
      const uint32_t b = 3 * i;
      idx.insert(idx.end(), {b + i % 3, b + (i + 1) % 3, b + (i + 2) % 3});
    }
    cases.push_back(build(p, idx));
  }
  for (const auto& a : cases) {
    for (auto method : {tc::RebuildMethod::Lbvh, tc::RebuildMethod::HlbvhSah}) {
      SCOPED_TRACE(std::to_string(a.triangleCount()) + " triangles, " + tc::rebuildMethodName(method));
      tsah::Bvh one;
      one.nodes.resize(1);
      one.nodes[0].primCount = a.triangleCount();
      for (uint32_t i = 0; i < a.triangleCount(); ++i) one.primIds.push_back(i);
      one.boxes.resize(1);
      const tsah::PrimitiveBoxes prims0 = boxesAt(a, 0.0);
      for (const auto& b : prims0.boxes) one.boxes[0].extend(b);
      tc::GpuRuntime gpu(tsah::flattenBvh(one), a);
      for (bool collapse : {false, true}) {
        tc::RebuildOptions o;
        o.method = method;
        o.collapse = collapse;
        gpu.rebuildAt(0.5, o);
        const tsah::Bvh bvh = gpu.downloadRebuiltTree();
        const tsah::PrimitiveBoxes prims = boxesAt(a, 0.5);
        ASSERT_FALSE(tsah::validate(bvh, &prims).has_value()) << *tsah::validate(bvh, &prims);
        EXPECT_EQ(bvh.primCount(), a.triangleCount());
        if (!collapse) {
          EXPECT_EQ(largestLeaf(bvh), 1u);
        }
        tsah::CpuRuntime cpu = cpuRuntime(tsah::flattenBvh(one), a);
        cpu.update(a.positionsAt(0.5));
        const tsah::BvhView v = cpu.view();
        std::vector<tsah::Ray> rays;
        for (int i = 0; i < 64; ++i)  // straight down onto the plane of the triangles
          rays.push_back({{0.02f + 0.03f * float(i % 8), 0.02f + 0.03f * float(i / 8), 5.0f}, 0.0f, {0, 0, -1}, 1e30f});
        const auto hits = gpu.closestHits(rays);
        for (std::size_t i = 0; i < rays.size(); ++i) {
          const tsah::Hit expect = tsah::closestHit(v, rays[i]);
          ASSERT_EQ(expect.valid(), hits[i].valid());
          if (expect.valid()) {
            ASSERT_NEAR(expect.t, hits[i].t, 1e-5f * expect.t);
          }
        }
      }
    }
  }
}

}  // namespace

#else

TEST(CudaRuntime, NotBuilt) { GTEST_SKIP() << "built without the CUDA runtime"; }

#endif
