#include "optimizer_options.hpp"

#include <CLI/CLI.hpp>

namespace tsah::cli {

void addTreeOptions(CLI::App& sub, TreeOptions& tree, uint32_t& evalFrames) {
  sub.add_option("--frames", tree.frames, "Representative frames, uniform in time")
      ->check(CLI::Range(1u, 1000u))
      ->capture_default_str();
  sub.add_option("--eval-frames", evalFrames, "Evaluation frames for the reported cost, uniform in time")
      ->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
  sub.add_option("--max-leaf", tree.maxLeaf, "Largest leaf after collapse (1: one triangle per leaf)")
      ->check(CLI::Range(1u, 256u))
      ->capture_default_str();
  sub.add_option("--ct", tree.ct, "Cost of traversing a node")->check(CLI::PositiveNumber)->capture_default_str();
  sub.add_option("--ci", tree.ci, "Cost of intersecting a triangle")->check(CLI::PositiveNumber)->capture_default_str();
  sub.add_option("--optimizer", tree.optimizer,
                 "parallel (reinsertion on all cores) or sequential (the paper's Metropolis-Hastings insertion, one core)")
      ->check(CLI::IsMember({"sequential", "parallel"}))
      ->capture_default_str();
  sub.add_option("--selection", tree.selection,
                 "Node selection of the sequential optimizer: mh (Metropolis-Hastings), random, batch (batch sorting)")
      ->check(CLI::IsMember({"mh", "random", "batch"}))
      ->capture_default_str();
  sub.add_option("--seed", tree.seed, "Random seed (same seed and thread count, same tree)")->capture_default_str();
  sub.add_option("--time-limit", tree.timeLimit, "Stop each optimization after this many seconds (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub.add_option("--min-improvement", tree.minImprovement,
                 "Stop after 3 batches (rounds) that lower the cost by less than this fraction each (0: by nothing)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  sub.add_option("--threads", tree.threads, "Worker threads (0: all cores)")->capture_default_str();
}

}  // namespace tsah::cli
