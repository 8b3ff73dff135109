// The GPU runtime with a tree set: all trees uploaded once, updateAt(t) refits and traces the tree
// of t's part, exactly as the CPU runtime picks and refits it (boxes and Woop triangles bit for
// bit), boundaries and overlaps included. Skips without a CUDA device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cstring>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "cuda_test_support.hpp"
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
