// The GPU's closest-point and box-overlap queries against the CPU runtime's (the same traversal,
// no fused multiply-adds): the same triangles, distances and points, the same overlap lists, over
// several frames. Every test that needs a GPU skips without one.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cmath>
#include <random>

#include "anim/generators.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/queries.hpp"
#include "tsah_cuda/gpu_queries.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace {

using tsah::Aabb;
using tsah::Vec3;
namespace tc = tsah::cuda;

std::vector<Vec3> randomPoints(const Aabb& bounds, uint32_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.2f, 1.2f);
  const Vec3 size = bounds.extent();
  std::vector<Vec3> points;
  for (uint32_t i = 0; i < n; ++i) points.push_back(bounds.lo + Vec3{u(rng) * size.x, u(rng) * size.y, u(rng) * size.z});
  return points;
}

TEST(CudaQueries, EqualTheCpuRuntimesOverFrames) {
  REQUIRE_GPU();
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 4000, 6, 3);
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  const Aabb bounds = tsah::test::boxOf(a.bounds());
  const float diagonal = std::sqrt(tsah::dot(bounds.extent(), bounds.extent()));
  tsah::CpuRuntime cpu(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  tc::GpuRuntime gpu(tree, a);
  const std::vector<Vec3> points = randomPoints(bounds, 5000, 7);
  std::vector<float> radii;
  std::mt19937 rng(9);
  for (std::size_t i = 0; i < points.size(); ++i)
    radii.push_back(i % 4 == 0 ? INFINITY : diagonal * std::uniform_real_distribution<float>(0.01f, 0.2f)(rng));
  std::vector<Aabb> boxes;
  for (const Vec3& c : randomPoints(bounds, 1000, 8)) {
    const Vec3 half = Vec3{1.0f, 1.0f, 1.0f} * (0.05f * diagonal);
    boxes.push_back(Aabb{c - half, c + half});
  }
  for (double t : a.uniformTimes(3)) {
    SCOPED_TRACE(t);
    cpu.update(a.positionsAt(t));
    gpu.updateAt(t);
    const std::vector<tsah::PointHit> want = tsah::closestPoints(cpu, points, radii);
    tsah::RayPassStats stats;
    const std::vector<tsah::PointHit> got = tc::closestPoints(gpu, points, radii, &stats);
    ASSERT_EQ(got.size(), want.size());
    EXPECT_EQ(stats.rays, points.size());
    uint32_t found = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      ASSERT_EQ(got[i].tri, want[i].tri) << "point " << i;
      if (!want[i].valid()) {
        EXPECT_TRUE(std::isinf(got[i].distance));
        continue;
      }
      ++found;
      EXPECT_NEAR(got[i].distance, want[i].distance, 1e-5f * std::max(want[i].distance, 1e-6f)) << "point " << i;
      EXPECT_NEAR(got[i].u, want[i].u, 1e-5f);
      EXPECT_NEAR(got[i].v, want[i].v, 1e-5f);
    }
    EXPECT_GT(found, 0u);
    const tsah::BoxOverlaps wantBoxes = tsah::overlappingTriangles(cpu, boxes);
    const tsah::BoxOverlaps gotBoxes = tc::overlappingTriangles(gpu, boxes);
    EXPECT_EQ(gotBoxes.offsets, wantBoxes.offsets);
    EXPECT_EQ(gotBoxes.triangles, wantBoxes.triangles);
    EXPECT_GT(wantBoxes.triangles.size(), 0u);
  }
}

TEST(CudaQueries, RefuseCwbvhBadInputsAndQueriesBeforeAnUpdate) {
  REQUIRE_GPU();
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 800, 3);
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  const std::vector<Vec3> points{{0, 0, 0}};
  tc::GpuRuntime gpu(tree, a);
  EXPECT_THROW(tc::closestPoints(gpu, points, std::vector<float>{1.0f}), tsah::ConfigError);
  gpu.updateAt(a.startTime());
  EXPECT_EQ(tc::closestPoints(gpu, points, std::vector<float>{INFINITY}).size(), 1u);
  EXPECT_THROW(tc::closestPoints(gpu, points, std::vector<float>{-1.0f}), tsah::ConfigError);
  tc::GpuRuntime::Config config;
  config.layout = tsah::Layout::Cwbvh;
  tc::GpuRuntime wide(tree, a, config);
  wide.updateAt(a.startTime());
  EXPECT_THROW(tc::closestPoints(wide, points, std::vector<float>{1.0f}), tsah::ConfigError);
  EXPECT_THROW(tc::overlappingTriangles(wide, std::vector<Aabb>{Aabb{{0, 0, 0}, {1, 1, 1}}}), tsah::ConfigError);
}

}  // namespace

#else

TEST(CudaQueries, NotBuilt) { GTEST_SKIP() << "built without the CUDA runtime"; }

#endif
