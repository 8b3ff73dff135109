#include "optimizer_options.hpp"

#include <CLI/CLI.hpp>

#include "animation_frames.hpp"

namespace tsah::cli {

void OptimizerOptions::addTo(CLI::App& sub) {
  sub.add_option("--frames", frames, "Representative frames, uniform in time")
      ->check(CLI::Range(1u, 1000u))
      ->capture_default_str();
  sub.add_option("--eval-frames", evalFrames, "Evaluation frames for the reported cost, uniform in time")
      ->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
  sub.add_option("--max-leaf", maxLeaf, "Largest leaf after collapse (1: one triangle per leaf)")
      ->check(CLI::Range(1u, 256u))
      ->capture_default_str();
  sub.add_option("--ct", ct, "Cost of traversing a node")->check(CLI::PositiveNumber)->capture_default_str();
  sub.add_option("--ci", ci, "Cost of intersecting a triangle")->check(CLI::PositiveNumber)->capture_default_str();
  sub.add_option("--optimizer", optimizer,
                 "parallel (reinsertion on all cores) or sequential (the paper's Metropolis-Hastings insertion, one core)")
      ->check(CLI::IsMember({"sequential", "parallel"}))
      ->capture_default_str();
  sub.add_option("--selection", selection,
                 "Node selection of the sequential optimizer: mh (Metropolis-Hastings), random, batch (batch sorting)")
      ->check(CLI::IsMember({"mh", "random", "batch"}))
      ->capture_default_str();
  sub.add_option("--seed", seed, "Random seed (same seed and thread count, same tree)")->capture_default_str();
  sub.add_option("--time-limit", timeLimit, "Stop each optimization after this many seconds (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub.add_option("--min-improvement", minImprovement,
                 "Stop after 3 batches (rounds) that lower the cost by less than this fraction each (0: by nothing)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  sub.add_option("--threads", threads, "Worker threads (0: all cores)")->capture_default_str();
}

BaselineConfig OptimizerOptions::baselineConfig(std::function<void(const std::string&)> progress) const {
  BaselineConfig config;
  config.cost = {ct, ci};
  config.maxLeafSize = maxLeaf;
  config.threads = threads;
  config.optimizer.selection = parseSelection(selection);
  config.optimizer.seed = seed;
  config.optimizer.timeLimitSeconds = timeLimit;
  config.optimizer.minImprovement = minImprovement;
  config.optimizerKind = parseOptimizerKind(optimizer);
  config.parallel.threads = threads;
  config.progress = std::move(progress);
  return config;
}

}  // namespace tsah::cli
