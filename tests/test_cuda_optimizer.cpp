// The GPU optimizer's kernels (cuda_kernels/src/reinsertion.cu) against their host emulation: the
// same tree bit for bit for a seed, tree invariants and exact cost tracking after every round on the
// device, quality against the CPU parallel optimizer. Skips without a device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "anim/generators.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/optimize/detail/reinsertion_emulation.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_optimizer.hpp"

namespace {

using tsah::Bvh;
using tsah::ParallelReinsertionOptimizer;

using tsah::test::frameZeroSahTree;
using tsah::test::movingTriangleBoxes;

TEST(CudaOptimizer, SameTreeAsTheEmulation) {
  REQUIRE_GPU();
  struct Case {
    uint32_t triangles, frames, seed;
    int k;
    double fraction;
  };
  const std::vector<Case> cases =
      tsah::test::shortCudaRun() ? std::vector<Case>{{300, 1, 1, 0, 0.5}, {1000, 3, 5, 2, 0.5}}
                 : std::vector<Case>{{300, 1, 1, 0, 0.5}, {2000, 4, 2, 0, 0.25}, {2000, 5, 3, 2, 0.25},
                                     {20000, 5, 4, 0, 0.25}, {20000, 3, 5, 1, 0.5}};
  for (const Case& c : cases) {
    const tsah::PrimitiveBoxes prims = movingTriangleBoxes(c.triangles, c.frames, c.seed);
    ParallelReinsertionOptimizer::Config config;
    config.k = c.k;
    config.seed = c.seed;
    if (tsah::test::shortCudaRun()) config.maxBatches = 12;
    ParallelReinsertionOptimizer::Parallel parallel;
    parallel.candidateFraction = c.fraction;
    const auto gpu = tsah::cuda::optimizeOnGpu(frameZeroSahTree(prims), prims, config, parallel);
    const auto emulated = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, config, parallel);
    std::printf("%u triangles x %u frames, k %d: GPU %.6f emulated %.6f, %zu rounds, %.3f s on the GPU\n",
                c.triangles, c.frames, c.k, gpu.finalCost, emulated.finalCost, gpu.history.size() - 1, gpu.seconds);
    EXPECT_TRUE(tsah::test::identicalTree(gpu.bvh, emulated.bvh)) << c.triangles << " triangles, seed " << c.seed;
    EXPECT_EQ(gpu.finalCost, emulated.finalCost);
    EXPECT_EQ(gpu.acceptedSteps, emulated.acceptedSteps);
    ASSERT_EQ(gpu.history.size(), emulated.history.size());
    for (std::size_t i = 0; i < gpu.history.size(); ++i)
      EXPECT_EQ(gpu.history[i].cost, emulated.history[i].cost) << "round " << i;
  }
}

// Every search variant (general or frame-specialized, one thread per candidate or persistent
// threads) finds the same moves: the emulation's tree, whichever kernel ran.
TEST(CudaOptimizer, EverySearchVariantGivesTheSameTree) {
  REQUIRE_GPU();
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(tsah::test::shortCudaRun() ? 1000 : 5000, 5, 31);
  ParallelReinsertionOptimizer::Config config;
  config.maxBatches = tsah::test::shortCudaRun() ? 10 : 40;
  const auto emulated = tsah::optimizeEmulatedDevice(frameZeroSahTree(prims), prims, config, {});
  for (const bool specialized : {false, true})
    for (const bool dynamic : {false, true}) {
      std::vector<tsah::cuda::GpuPhaseTime> times;
      std::size_t bytes = 0;
      const auto gpu = tsah::cuda::profileOnGpu(frameZeroSahTree(prims), prims, config, {}, times, bytes,
                                                tsah::cuda::GpuSearchKernel{specialized, dynamic});
      EXPECT_TRUE(tsah::test::identicalTree(gpu.bvh, emulated.bvh))
          << "specialized " << specialized << " dynamic " << dynamic;
      EXPECT_EQ(gpu.finalCost, emulated.finalCost);
      EXPECT_FALSE(times.empty());
      EXPECT_GT(bytes, std::size_t(prims.primCount) * 240);  // at least the interior and primitive boxes
    }
}

TEST(CudaOptimizer, InvariantsAndExactCostAfterEveryRound) {
  REQUIRE_GPU();
  for (uint32_t frames : {1u, 4u}) {
    for (int k : {0, 2}) {
      const tsah::PrimitiveBoxes prims = movingTriangleBoxes(tsah::test::shortCudaRun() ? 600 : 3000, frames, 20 + frames);
      ParallelReinsertionOptimizer::Config config;
      config.k = k;
      const auto session = tsah::cuda::makeGpuReinsertionSession(frameZeroSahTree(prims), prims, config, {});
      const double start = session->cost();
      const uint64_t applied = tsah::test::expectValidRounds(*session, prims, k, tsah::test::shortCudaRun() ? 6 : 15);
      EXPECT_GT(applied, 0u);
      EXPECT_LT(session->cost(), start);
    }
  }
}

TEST(CudaOptimizer, WithinTwoPercentOfTheCpuParallelOptimizer) {
  REQUIRE_GPU();
  const std::vector<uint32_t> seeds = tsah::test::shortCudaRun() ? std::vector<uint32_t>{11} : std::vector<uint32_t>{11, 12, 13};
  const std::vector<int> exponents = tsah::test::shortCudaRun() ? std::vector<int>{0} : std::vector<int>{0, 2};
  for (uint32_t seed : seeds) {
    for (int k : exponents) {
      const tsah::PrimitiveBoxes prims = movingTriangleBoxes(tsah::test::shortCudaRun() ? 600 : 20000, 5, seed);
      ParallelReinsertionOptimizer::Config config;
      config.k = k;
      config.seed = seed;
      const auto cpu = ParallelReinsertionOptimizer(config).optimize(frameZeroSahTree(prims), prims);
      const auto gpu = tsah::cuda::optimizeOnGpu(frameZeroSahTree(prims), prims, config, {});
      ASSERT_FALSE(tsah::validate(gpu.bvh, &prims).has_value());
      EXPECT_LT(gpu.finalCost, gpu.initialCost);
      std::printf("seed %u k %d: GPU / CPU parallel = %.4f (GPU %.3f s, CPU %.3f s)\n", seed, k,
                  gpu.finalCost / cpu.finalCost, gpu.seconds, cpu.seconds);
      EXPECT_LT(gpu.finalCost, 1.02 * cpu.finalCost) << "seed " << seed << " k " << k;
    }
  }
}

TEST(CudaOptimizer, CollapseAndBadInput) {
  REQUIRE_GPU();
  const tsah::PrimitiveBoxes prims = movingTriangleBoxes(1200, 3, 80);
  const tsah::LeafCollapser collapser({0, {}, 4});
  ParallelReinsertionOptimizer::Config config;
  if (tsah::test::shortCudaRun()) config.maxBatches = 10;
  const auto plain = tsah::cuda::optimizeOnGpu(frameZeroSahTree(prims), prims, config, {});
  const auto collapsed = tsah::cuda::optimizeOnGpu(frameZeroSahTree(prims), prims, config, {}, &collapser);
  EXPECT_TRUE(tsah::test::identicalTree(collapser.collapse(plain.bvh), collapsed.bvh));
  for (uint32_t count : {1u, 2u, 3u}) {
    const tsah::PrimitiveBoxes few = movingTriangleBoxes(count, 2, 60 + count);
    const auto result = tsah::cuda::optimizeOnGpu(frameZeroSahTree(few), few, {}, {});
    EXPECT_FALSE(tsah::validate(result.bvh, &few).has_value());
  }
  const tsah::PrimitiveBoxes many = movingTriangleBoxes(50, 17, 81);
  EXPECT_THROW(tsah::cuda::makeGpuReinsertionSession(frameZeroSahTree(many), many, {}, {}), tsah::ConfigError);
}

// Where the time goes on a generated explode animation (10 keyframes, 5 representative frames):
// the plain run, then a run with every phase timed. TSAH_PROFILE_TRIANGLES (default 200000) sets
// the size, TSAH_PROFILE_CPU=1 adds the CPU parallel optimizer for the cost ratio. Disabled by
// default (a benchmark): --gtest_also_run_disabled_tests --gtest_filter='*Profile*'.
TEST(CudaOptimizer, DISABLED_ProfileExplode) {
  REQUIRE_GPU();
  const char* size = std::getenv("TSAH_PROFILE_TRIANGLES");
  const uint32_t triangles = size ? uint32_t(std::stoul(size)) : 200000u;
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Explode, triangles, 10);
  const tsah::PrimitiveBoxes prims = tsah::representativeBoxes(a, 5);
  std::printf("explode: %u triangles x %u frames\n", prims.primCount, prims.frameCount);
  ParallelReinsertionOptimizer::Config config;
  const auto gpu = tsah::cuda::optimizeOnGpu(frameZeroSahTree(prims), prims, config, {});
  ASSERT_FALSE(tsah::validate(gpu.bvh, &prims).has_value());
  EXPECT_LT(gpu.finalCost, gpu.initialCost);
  std::printf("GPU: %.3f s, %zu rounds, cost %.4f -> %.4f, %llu moves\n", gpu.seconds, gpu.history.size() - 1,
              gpu.initialCost, gpu.finalCost, static_cast<unsigned long long>(gpu.acceptedSteps));
  for (const tsah::cuda::GpuSearchKernel search : {tsah::cuda::GpuSearchKernel{false, false},
                                                   tsah::cuda::GpuSearchKernel{true, false},
                                                   tsah::cuda::GpuSearchKernel{false, true},
                                                   tsah::cuda::GpuSearchKernel{true, true}}) {
    std::vector<tsah::cuda::GpuPhaseTime> times;
    std::size_t bytes = 0;
    const auto profiled = tsah::cuda::profileOnGpu(frameZeroSahTree(prims), prims, config, {}, times, bytes, search);
    EXPECT_EQ(profiled.finalCost, gpu.finalCost);
    std::printf("profiled (%s search, %s): %.3f s; device buffers %.1f B per triangle\n",
                search.specializedFrames ? "frame-specialized" : "general",
                search.dynamicFetch ? "persistent threads" : "one thread per candidate", profiled.seconds,
                double(bytes) / prims.primCount);
    for (const auto& t : times)
      std::printf("  %-22s %8.4f s  %6llu launches\n", t.phase.c_str(), t.seconds,
                  static_cast<unsigned long long>(t.launches));
  }
  if (const char* cpu = std::getenv("TSAH_PROFILE_CPU"); cpu && std::string(cpu) == "1") {
    const auto parallel = ParallelReinsertionOptimizer(config).optimize(frameZeroSahTree(prims), prims);
    std::printf("CPU parallel: %.3f s, cost %.4f; GPU / CPU = %.4f\n", parallel.seconds, parallel.finalCost,
                gpu.finalCost / parallel.finalCost);
    EXPECT_LT(gpu.finalCost, 1.02 * parallel.finalCost);
  }
}

}  // namespace

#else
TEST(CudaOptimizer, NotBuilt) { GTEST_SKIP() << "built without CUDA"; }
#endif
