// The CPU runtime's per-frame update: the parallel refit gives exactly the boxes of a refit from
// scratch, and the Woop triangles of the frame, at any time and for any thread count.
#include <gtest/gtest.h>

#include <cstring>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/build/sah_builder.hpp"
#include "test_support.hpp"

namespace {

using tsah::test::generatedAnimation;

// The reference: tsah::refit over the Bvh with boxes computed from scratch, then flattened.
tsah::FlatBvh refitFromScratch(const tsah::Bvh& topology, const anim::Animation& a, double t) {
  tsah::Bvh bvh = topology;
  const auto pos = a.positionsAt(t);
  tsah::refit(bvh, tsah::triangleBoxes(a.indices(), pos, 1));
  return tsah::flattenBvh(bvh);
}

void expectSameBoxes(const tsah::FlatBvh& expect, const tsah::FlatBvh& got) {
  ASSERT_EQ(expect.interiorCount, got.interiorCount);
  ASSERT_EQ(0, std::memcmp(&expect.rootBoxes[0], &got.rootBoxes[0], sizeof(tsah::Aabb)));
  for (uint32_t i = 0; i < expect.interiorCount; ++i)
    ASSERT_EQ(0, std::memcmp(&expect.nodes[i], &got.nodes[i], sizeof(tsah::GpuBvhNode))) << "node " << i;
}

void checkRefit(const anim::Animation& a, const tsah::Bvh& topology, uint32_t threads) {
  // Start from a tree whose stored boxes belong to frame 0.
  const tsah::FlatBvh initial = refitFromScratch(topology, a, a.startTime());
  tsah::CpuRuntime rt(initial, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {threads});
  for (double t : a.uniformTimes(7)) {
    const auto pos = a.positionsAt(t);
    rt.update(pos);
    expectSameBoxes(refitFromScratch(topology, a, t), rt.tree());
    // Woop triangles of this frame, in slot order.
    const auto idx = a.indices();
    for (uint32_t s = 0; s < rt.triangleCount(); ++s) {
      const uint32_t tri = rt.tree().triIndex[s];
      auto v = [&](uint32_t k) {
        const uint32_t i = idx[3 * tri + k];
        return tsah::Vec3{pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]};
      };
      const tsah::WoopTriangle w = tsah::makeWoopTriangle(v(0), v(1), v(2));
      ASSERT_EQ(0, std::memcmp(&w, &rt.woop()[s], sizeof w)) << "slot " << s << " t=" << t;
    }
  }
}

TEST(Refit, EqualsRefitFromScratchAtSeveralTimes) {
  // 6000 triangles: enough nodes to split the refit into many parallel subtrees.
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 6000, 10);
  const std::vector<tsah::Aabb> boxes = tsah::test::keyframeBoxes(a, 0);
  const tsah::Bvh sweep = tsah::SweepSahBuilder().build(boxes);
  for (uint32_t threads : {1u, 2u, 7u}) checkRefit(a, sweep, threads);
  tsah::BinnedSahBuilder::Config c;
  c.maxLeafSize = 8;
  checkRefit(a, tsah::BinnedSahBuilder(c).build(boxes), 3);
}

TEST(Refit, WaveAndSwap) {
  for (auto kind : {anim::GeneratorKind::Wave, anim::GeneratorKind::Swap}) {
    const auto a = generatedAnimation(kind, 2000, 5);
    checkRefit(a, tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0)), 2);
  }
}

TEST(Refit, RebuildGivesAValidTreeOfTheFrame) {
  const auto a = generatedAnimation(anim::GeneratorKind::Explode, 3000, 4);
  const std::vector<tsah::Aabb> boxes = tsah::test::keyframeBoxes(a, 0);
  tsah::CpuRuntime rt(tsah::flattenBvh(tsah::SweepSahBuilder().build(boxes)),
                      {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  const tsah::BinnedSahBuilder builder;
  const double t = a.endTime();
  const auto timings = rt.rebuild(a.positionsAt(t), [&](std::span<const tsah::Aabb> b) { return builder.build(b); });
  EXPECT_GE(timings.buildMs, 0.0);
  EXPECT_FALSE(tsah::validateFlatBvh(rt.tree()));
  // The rebuilt tree's boxes are those of frame t.
  tsah::Bvh rebuilt = tsah::unflattenBvh(rt.tree());
  const tsah::PrimitiveBoxes frameBoxes = tsah::triangleBoxes(a.indices(), a.positionsAt(t), 1);
  EXPECT_FALSE(tsah::validate(rebuilt, &frameBoxes));
  expectSameBoxes(refitFromScratch(rebuilt, a, t), rt.tree());
  EXPECT_LE(rt.tree().depth, tsah::kTraversalStackSize);
}

TEST(Refit, RejectsMismatchedInput) {
  const auto a = generatedAnimation(anim::GeneratorKind::Wave, 500, 2);
  const std::vector<tsah::Aabb> boxes = tsah::test::keyframeBoxes(a, 0);
  const tsah::FlatBvh flat = tsah::flattenBvh(tsah::SweepSahBuilder().build(boxes));
  std::vector<uint32_t> idx(a.indices().begin(), a.indices().end());
  std::vector<uint32_t> fewer(idx.begin(), idx.end() - 3);
  EXPECT_THROW(tsah::CpuRuntime(flat, fewer, a.vertexCount()), tsah::DataError);
  std::vector<uint32_t> outOfRange = idx;
  outOfRange[5] = a.vertexCount();
  EXPECT_THROW(tsah::CpuRuntime(flat, outOfRange, a.vertexCount()), tsah::DataError);
  tsah::CpuRuntime rt(flat, idx, a.vertexCount());
  std::vector<float> shortPositions(3 * a.vertexCount() - 3);
  EXPECT_THROW(rt.update(shortPositions), tsah::DataError);
}

}  // namespace
