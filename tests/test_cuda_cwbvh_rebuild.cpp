// The per-frame GPU rebuilds (LBVH, HLBVH-SAH) in the compressed 8-wide layout (GpuRuntime with
// Config::layout = cwbvh): the device's conversion of the rebuilt binary tree equals the host
// emulation (tsah::convertToCwbvh) run on the downloaded binary arrays, byte for byte, frame after
// frame and with or without CUDA graphs; the Woop triangles are those of the wide slots; traced
// hits equal the host reference traversal of the same layout exactly and the binary rebuild's up to
// ties; rendered images equal the binary rebuild's. Skipped without a device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cstdlib>
#include <cstring>
#include <string>
#include <random>

#include "tsah/base/error.hpp"
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

namespace tc = tsah::cuda;

using tsah::test::generatedAnimation;
using tsah::test::gpuConfig;
using tsah::test::traceHits;

tsah::FlatBvh frameZeroTree(const anim::Animation& a) {
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(a.indices(), a.positionsAt(a.startTime()), 1);
  return tsah::flattenBvh(tsah::SweepSahBuilder().build(boxes.frame(0)));
}

tc::RebuildOptions options(tc::RebuildMethod method, bool collapse) {
  tc::RebuildOptions o;
  o.method = method;
  o.collapse = collapse;
  return o;
}

// The host emulation on the device's binary arrays.
tsah::CwbvhTree hostConversion(const tc::GpuRuntime& gpu, uint32_t merge = tsah::kCwbvhDefaultMergeTriangles) {
  const tsah::FlatBvh raw = gpu.downloadRebuiltArrays();
  const tsah::BinaryTreeView view{raw.nodes.data(), raw.interiorCount, raw.triIndex.data(), raw.triangleCount()};
  return tsah::convertToCwbvh(view, raw.rootRef, raw.rootCount, raw.rootBoxes[0], merge);
}

void expectEqualToHost(const tc::GpuRuntime& gpu, const tc::RebuildTimings& timings, const anim::Animation& a,
                       double t, uint32_t merge = tsah::kCwbvhDefaultMergeTriangles) {
  const tsah::CwbvhTree host = hostConversion(gpu, merge);
  ASSERT_EQ(tsah::validateCwbvh(host), std::nullopt);
  const tsah::CwbvhTree device = gpu.downloadRebuiltCwbvh();
  ASSERT_EQ(device.nodes.size(), host.nodes.size()) << "t=" << t;
  EXPECT_EQ(timings.wideNodes, host.nodeCount());
  EXPECT_EQ(timings.wideLevels, host.depth);  // the last level holds only leaves
  EXPECT_EQ(std::memcmp(device.nodes.data(), host.nodes.data(), host.nodes.size() * sizeof(tsah::CwbvhNode)), 0)
      << "t=" << t;
  EXPECT_EQ(device.triIndex, host.triIndex) << "t=" << t;
  const auto pos = a.positionsAt(t);
  const std::vector<tsah::WoopTriangle> woop = tsah::test::cwbvhWoop(host, a.indices(), pos);
  const std::vector<tsah::WoopTriangle> deviceWoop = gpu.downloadWoop();
  EXPECT_EQ(std::memcmp(woop.data(), deviceWoop.data(), woop.size() * sizeof woop[0]), 0) << "t=" << t;
}

TEST(CudaCwbvhRebuild, ConversionEqualsHostEmulation) {
  REQUIRE_GPU();
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave}) {
    const anim::Animation a = generatedAnimation(kind, tsah::test::shortCudaRun() ? 3000 : 30000, 6);
    const tsah::FlatBvh tree = frameZeroTree(a);
    tc::GpuRuntime gpu(tree, a, gpuConfig(tsah::Layout::Cwbvh));
    for (auto method : {tc::RebuildMethod::Lbvh, tc::RebuildMethod::HlbvhSah})
      for (bool collapse : {true, false})
        for (double t : {a.startTime(), 2.5, a.endTime()}) {
          SCOPED_TRACE(std::string(tc::rebuildMethodName(method)) + (collapse ? " collapsed" : " bare"));
          const tc::RebuildTimings timings = gpu.rebuildAt(t, options(method, collapse));
          EXPECT_GT(timings.wideMs, 0.0);
          EXPECT_GE(timings.totalMs(), timings.buildMs() + timings.wideMs);
          expectEqualToHost(gpu, timings, a, t);
        }
    for (uint32_t merge : {2u, 3u, 8u}) {  // RebuildOptions::wideMergeTriangles (default 0)
      tc::RebuildOptions o = options(tc::RebuildMethod::HlbvhSah, false);
      o.wideMergeTriangles = merge;
      const tc::RebuildTimings timings = gpu.rebuildAt(1.0, o);
      expectEqualToHost(gpu, timings, a, 1.0, merge);
    }
  }
}

// Large enough that the widest levels take more than one round of the persistent kernel's threads
// (an H100 runs 264 blocks of 128),
// and replayed: the same input gives the same bytes, with and without a CUDA graph.
TEST(CudaCwbvhRebuild, LargeTreeDeterministicWithAndWithoutGraphs) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Explode, tsah::test::shortCudaRun() ? 20000 : 1000000, 3);
  const tsah::FlatBvh tree = frameZeroTree(a);
  tc::GpuRuntime graphs(tree, a, gpuConfig(tsah::Layout::Cwbvh, true));
  tc::GpuRuntime direct(tree, a, gpuConfig(tsah::Layout::Cwbvh, false));
  for (bool collapse : {false, true}) {
    const tc::RebuildOptions o = options(tc::RebuildMethod::Lbvh, collapse);
    const tc::RebuildTimings first = graphs.rebuildAt(1.0, o);
    expectEqualToHost(graphs, first, a, 1.0);
    const tsah::CwbvhTree once = graphs.downloadRebuiltCwbvh();
    graphs.rebuildAt(0.0, o);
    graphs.rebuildAt(1.0, o);
    const tsah::CwbvhTree again = graphs.downloadRebuiltCwbvh();
    direct.rebuildAt(1.0, o);
    const tsah::CwbvhTree plain = direct.downloadRebuiltCwbvh();
    for (const tsah::CwbvhTree* other : {&again, &plain}) {
      ASSERT_EQ(other->nodes.size(), once.nodes.size());
      EXPECT_EQ(std::memcmp(other->nodes.data(), once.nodes.data(), once.nodes.size() * sizeof(tsah::CwbvhNode)), 0);
      EXPECT_EQ(other->triIndex, once.triIndex);
    }
  }
}

TEST(CudaCwbvhRebuild, HitsEqualHostReferenceAndBinaryRebuild) {
  REQUIRE_GPU();
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Swap}) {
    const anim::Animation a = generatedAnimation(kind, 8000, 6);
    const tsah::FlatBvh tree = frameZeroTree(a);
    tc::GpuRuntime gpuWide(tree, a, gpuConfig(tsah::Layout::Cwbvh));
    tc::GpuRuntime gpuBinary(tree, a, gpuConfig(tsah::Layout::Bvh2));
    for (auto method : {tc::RebuildMethod::Lbvh, tc::RebuildMethod::HlbvhSah}) {
      tsah::test::HitAgreement count;
      for (double t : {0.0, 2.3}) {
        gpuWide.rebuildAt(t, options(method, true));
        gpuBinary.rebuildAt(t, options(method, true));
        ASSERT_TRUE(gpuWide.tracingRebuiltTree());
        const auto pos = a.positionsAt(t);
        const tsah::CwbvhTree host = hostConversion(gpuWide);
        const auto woop = tsah::test::cwbvhWoop(host, a.indices(), pos);
        const tsah::CwbvhView view = host.view(woop.data(), a.indices().data(), pos.data());
        tsah::BvhView box;  // only for the rays' triangles
        box.indices = a.indices().data();
        box.positions = pos.data();
        std::mt19937 rng(17);
        const auto rays = tsah::test::randomRays(box, a.triangleCount(), gpuBinary.bounds(), 20000, rng);
        ASSERT_NO_FATAL_FAILURE(
            tsah::test::expectWideHitsMatch(view, rays, traceHits(gpuWide, rays), traceHits(gpuBinary, rays), count));
      }
      EXPECT_GT(count.hits, 10000u) << tc::rebuildMethodName(method);
      EXPECT_LE(count.ties, count.hits / 100) << tc::rebuildMethodName(method);
    }
  }
}

TEST(CudaCwbvhRebuild, ImagesEqualBinaryRebuild) {
  REQUIRE_GPU();
  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Explode, 20000, 5);
  const tsah::FlatBvh tree = frameZeroTree(a);
  tc::GpuRuntime gpuWide(tree, a, gpuConfig(tsah::Layout::Cwbvh));
  tc::GpuRuntime gpuBinary(tree, a, gpuConfig(tsah::Layout::Bvh2));
  auto [bounds, settings, camera] = tsah::test::renderView(a);
  const tsah::SceneLighting lighting = tsah::fitLighting(bounds, camera);
  for (auto method : {tc::RebuildMethod::Lbvh, tc::RebuildMethod::HlbvhSah}) {
    settings.frame = 2;
    const double t = a.uniformTimes(5)[2];
    gpuWide.rebuildAt(t, options(method, true));
    gpuBinary.rebuildAt(t, options(method, true));
    tsah::Image wideImage, binaryImage;
    const tsah::RenderStats w = tc::renderFrameGpu(gpuWide, camera, lighting, settings, wideImage);
    const tsah::RenderStats b = tc::renderFrameGpu(gpuBinary, camera, lighting, settings, binaryImage);
    tsah::test::expectRayCountsClose(w, b);
    tsah::test::expectImagesClose(wideImage, binaryImage, tc::rebuildMethodName(method));
  }
}

// One triangle (the rebuilt tree is one leaf: the wide tree is a root node with one leaf child),
// leaves too large for a wide node, and switching back to the refitted tree.
TEST(CudaCwbvhRebuild, TinySceneLargeLeavesAndBackToRefit) {
  REQUIRE_GPU();
  const auto m = tsah::test::randomMovingTriangles(1, 2, 4, 0.1f);
  const anim::Animation one(m.indices, 3, m.positions, {0.0, 1.0});
  tc::GpuRuntime tiny(frameZeroTree(one), one, gpuConfig(tsah::Layout::Cwbvh));
  const tc::RebuildTimings timings = tiny.rebuildAt(0.0, options(tc::RebuildMethod::Lbvh, true));
  EXPECT_EQ(timings.wideNodes, 1u);
  expectEqualToHost(tiny, timings, one, 0.0);

  const anim::Animation a = generatedAnimation(anim::GeneratorKind::Wave, 5000, 3);
  tc::GpuRuntime gpu(frameZeroTree(a), a, gpuConfig(tsah::Layout::Cwbvh));
  tc::RebuildOptions large = options(tc::RebuildMethod::HlbvhSah, true);
  large.maxLeafSize = 16;  // 8 leaves of 16 would overflow a node's 64 triangles
  EXPECT_THROW(gpu.rebuildAt(0.0, large), tsah::Error);
  gpu.rebuildAt(0.0, options(tc::RebuildMethod::HlbvhSah, true));
  EXPECT_TRUE(gpu.tracingRebuiltTree());
  gpu.updateAt(0.0);
  EXPECT_FALSE(gpu.tracingRebuiltTree());
  EXPECT_EQ(gpu.downloadCwbvhNodes().size(), tsah::buildCwbvh(frameZeroTree(a)).nodes.size());
  // The binary layout keeps binary rebuilds.
  tc::GpuRuntime binary(frameZeroTree(a), a, gpuConfig(tsah::Layout::Bvh2));
  const tc::RebuildTimings b = binary.rebuildAt(0.0, large);
  EXPECT_EQ(b.wideMs, 0.0);
  EXPECT_EQ(b.wideNodes, 0u);
  EXPECT_THROW(binary.downloadRebuiltCwbvh(), tsah::Error);
}

}  // namespace

#else
TEST(CudaCwbvhRebuild, NotBuilt) { GTEST_SKIP() << "built without CUDA"; }
#endif
