#include "optimizer_options.hpp"

#include <CLI/CLI.hpp>

#include "cli.hpp"

#if TSAH_HAVE_CUDA
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_optimizer.hpp"
#endif

namespace tsah::cli {

void addTreeOptions(CLI::App& sub, TreeOptions& tree, uint32_t& evalFrames) {
  sub.add_option("--frames", tree.frames, "Representative frames, uniform in time")
      ->check(CLI::Range(1u, TreeOptions::kMaxFrames))
      ->capture_default_str();
  sub.add_option("--eval-frames", evalFrames, "Evaluation frames for the reported cost, uniform in time")
      ->check(CLI::Range(1u, TreeOptions::kMaxEvalFrames))
      ->capture_default_str();
  sub.add_option("--max-leaf", tree.objective.maxLeafSize, "Largest leaf after collapse (1: one triangle per leaf)")
      ->check(CLI::Range(1u, 256u))
      ->capture_default_str();
  sub.add_option("--ct", tree.objective.cost.ct, "Cost of traversing a node")->check(CLI::PositiveNumber)->capture_default_str();
  sub.add_option("--ci", tree.objective.cost.ci, "Cost of intersecting a triangle")->check(CLI::PositiveNumber)->capture_default_str();
  addChoice(sub, "--optimizer", tree.optimizer,
            "parallel (reinsertion on all cores) or sequential (the paper's Metropolis-Hastings insertion, one core)",
            {OptimizerKind::Sequential, OptimizerKind::Parallel});
  addChoice(sub, "--selection", tree.selection,
            "Node selection of the sequential optimizer: mh (Metropolis-Hastings), random, batch (batch sorting)",
            {Selection::MetropolisHastings, Selection::Uniform, Selection::BatchSort});
  sub.add_option("--seed", tree.seed, "Random seed (same seed and thread count, same tree)")->capture_default_str();
  sub.add_option("--time-limit", tree.timeLimit, "Stop each optimization after this many seconds (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub.add_option("--min-improvement", tree.minImprovement,
                 "Stop after 3 batches (rounds) that lower the cost by less than this fraction each (0: by nothing)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  sub.add_option("--threads", tree.threads, "Worker threads (0: all cores)")->capture_default_str();
  addChoice(sub, "--device", tree.device,
            "cpu, or cuda: optimize with the parallel reinsertion optimizer on the GPU (--optimizer is then unused)",
            {Device::Cpu, Device::Cuda});
#if TSAH_HAVE_CUDA
  tree.gpuOptimizer = cuda::gpuTreeOptimizer();
#endif
}

void checkTreeDevice(const TreeOptions& tree) {
  if (tree.device != Device::Cuda) return;
#if TSAH_HAVE_CUDA
  if (!cuda::deviceAvailable())
    throw UsageError("--device cuda: no CUDA device found (no GPU, no NVIDIA driver, or CUDA_VISIBLE_DEVICES hides "
                     "them); use --device cpu");
#else
  throw UsageError("--device cuda: the GPU optimizer is not built in this version of tsah (configure with a CUDA "
                   "compiler to build it); use --device cpu");
#endif
}

}  // namespace tsah::cli
