// The GPU optimizer's rounds (tsah/reinsertion_rounds.hpp) run by the serial host emulation: tree
// invariants and exact cost tracking after every round, never above the start, determinism, and
// quality against the CPU parallel optimizer. test_cuda_optimizer checks that the real kernels give
// the emulation's tree.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <stdexcept>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "test_support.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/optimize/detail/reinsertion_emulation.hpp"
#include "tsah/build/sah_builder.hpp"

namespace {

using tsah::Bvh;
using tsah::ParallelReinsertionOptimizer;

using tsah::test::frameZeroSahTree;
using tsah::test::movingTriangleBoxes;

ParallelReinsertionOptimizer::Parallel fraction(double f) {
  ParallelReinsertionOptimizer::Parallel p;
  p.candidateFraction = f;
  return p;
}

TEST(EmulatedGpuOptimizer, InvariantsAndExactCostAfterEveryRound) {
  tsah::test::expectRoundsValidAndImproving(
      [](Bvh tree, const tsah::PrimitiveBoxes& prims, const ParallelReinsertionOptimizer::Config& config, double f) {
        return tsah::makeEmulatedDeviceSession(std::move(tree), prims, config, fraction(f));
      });
}

TEST(EmulatedGpuOptimizer, NeverEndsAboveItsStartAndHistoryIsMonotone) {
  tsah::test::expectRunsNeverEndAboveTheStart(
      [](Bvh tree, const tsah::PrimitiveBoxes& prims, const ParallelReinsertionOptimizer::Config& config) {
        return tsah::optimizeEmulatedDevice(std::move(tree), prims, config, {});
      });
}

TEST(EmulatedGpuOptimizer, SameSeedSameTree) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(1500, 3, 41);
  ParallelReinsertionOptimizer::Config config;
  config.seed = 99;
  config.k = 2;
  const auto one = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, config, {});
  const auto again = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, config, {});
  EXPECT_TRUE(tsah::test::identicalTree(one.bvh, again.bvh));
  EXPECT_EQ(one.finalCost, again.finalCost);
  EXPECT_EQ(one.acceptedSteps, again.acceptedSteps);
  config.seed = 100;
  const auto otherSeed = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, config, {});
  EXPECT_FALSE(tsah::test::sameTopology(one.bvh, otherSeed.bvh));
}

TEST(EmulatedGpuOptimizer, WithinTwoPercentOfTheCpuParallelOptimizer) {
  for (uint32_t seed : {11u, 12u, 13u}) {
    for (int k : {0, 2}) {
      const tsah::PrimitiveBoxes prims = movingTriangleBoxes(2000, 5, seed);
      ParallelReinsertionOptimizer::Config config;
      config.k = k;
      config.seed = seed;
      const auto cpu = ParallelReinsertionOptimizer(config).optimize(frameZeroSahTree(prims), prims);
      const auto gpu = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, config, {});
      std::printf("seed %u k %d: emulated GPU / CPU parallel = %.4f\n", seed, k, gpu.finalCost / cpu.finalCost);
      EXPECT_LT(gpu.finalCost, 1.02 * cpu.finalCost) << "seed " << seed << " k " << k;
    }
  }
}

// The device buffers of a whole run at 5 frames, one triangle per leaf: boxes of the interior nodes
// and the primitives (240 B per triangle) plus links and round state; per-move arrays grow only to
// the largest round.
TEST(EmulatedGpuOptimizer, DeviceMemoryPerTriangle) {
  const uint32_t triangles = 8000;
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(triangles, 5, 90);
  std::size_t bytes = 0;
  const auto result = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, {}, {}, nullptr, &bytes);
  EXPECT_LT(result.finalCost, result.initialCost);
  const double perTriangle = double(bytes) / triangles;
  std::printf("device buffers: %.1f B per triangle (5 frames)\n", perTriangle);
  EXPECT_GT(perTriangle, 240.0);
  EXPECT_LT(perTriangle, 400.0);
}

TEST(EmulatedGpuOptimizer, CollapseLimitsAndBadInput) {
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(1200, 3, 80);
  const tsah::LeafCollapser collapser({0, {}, 4});
  const auto plain = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, {}, {});
  const auto collapsed = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, {}, {}, &collapser);
  EXPECT_TRUE(tsah::test::identicalTree(collapser.collapse(plain.bvh), collapsed.bvh));

  ParallelReinsertionOptimizer::Config rounds;
  rounds.maxBatches = 2;
  EXPECT_EQ(tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, rounds, {}).history.size(), 3u);

  for (uint32_t count : {1u, 2u, 3u}) {  // no eligible node: the tree comes back unchanged
    const tsah::PrimitiveBoxes few = movingTriangleBoxes(count, 2, 60 + count);
    const auto result = tsah::optimizeEmulatedDevice(frameZeroSahTree(few), few, {}, {});
    EXPECT_FALSE(tsah::validate(result.bvh, &few).has_value());
    EXPECT_EQ(result.acceptedSteps, 0u);
  }
  const tsah::PrimitiveBoxes many = movingTriangleBoxes(50, 17, 81);
  EXPECT_THROW(tsah::makeEmulatedDeviceSession(frameZeroSahTree(many), many, {}, {}), tsah::ConfigError);
  const tsah::PrimitiveBoxes other = movingTriangleBoxes(5, 2, 62);
  EXPECT_THROW(tsah::makeEmulatedDeviceSession(frameZeroSahTree(prims), other, {}, {}), tsah::DataError);
}

// The pipeline's --device cuda path with the emulation standing in for the GPU: every optimization
// of T-SAH and SAH* goes through TreeOptions::gpuOptimizer, collapsed as usual; without one,
// --device cuda is refused with one line.
TEST(EmulatedGpuOptimizer, PipelineRunsEveryOptimizationThroughTheDeviceHook) {
  anim::GeneratorOptions g;
  g.triangles = 1500;
  g.frames = 6;
  const anim::Animation a = anim::generate(anim::GeneratorKind::Explode, g);
  tsah::TreeOptions options;
  options.device = tsah::Device::Cuda;
  options.objective.k = 2;
  EXPECT_THROW(tsah::optimizeAnimation(a, options), tsah::Error);  // no GPU optimizer given
  std::atomic<int> calls = 0;  // SAH* optimizes its frames on worker threads
  options.gpuOptimizer = [&calls](Bvh bvh, const tsah::PrimitiveBoxes& prims,
                                  const tsah::InsertionOptimizer::Config& settings, const tsah::LeafCollapser* collapse) {
    ++calls;
    return tsah::optimizeEmulatedDevice(std::move(bvh), prims, settings, {}, collapse);
  };
  const tsah::OptimizedTree tree = tsah::optimizeAnimation(a, options);
  EXPECT_EQ(calls.load(), 1);
  EXPECT_EQ(tree.info.selection, "parallel-cuda");
  const tsah::PrimitiveBoxes rep = tsah::representativeBoxes(a, options.frames);
  EXPECT_FALSE(tsah::validate(tree.bvh, &rep).has_value());
  EXPECT_LT(tree.optimization.finalCost, tree.optimization.initialCost);
  // The same tree as the emulation on its own, collapsed the same way.
  tsah::InsertionOptimizer::Config config;
  config.k = 2;
  const tsah::LeafCollapser collapser({2, config.cost, options.objective.maxLeafSize});
  const auto direct = tsah::optimizeEmulatedDevice(tsah::SweepSahBuilder({config.cost, 1}).build(rep.frame(0)), rep,
                                                   config, {}, &collapser);
  EXPECT_TRUE(tsah::test::sameTopology(direct.bvh, tree.bvh));

  options.method = tsah::Method::SahStar;  // one optimization per representative frame
  calls = 0;
  tsah::optimizeAnimation(a, options);
  EXPECT_EQ(calls.load(), int(options.frames));
  EXPECT_THROW(tsah::parse<tsah::Device>("tpu"), tsah::ConfigError);  // names are refused where they are parsed
}

}  // namespace
