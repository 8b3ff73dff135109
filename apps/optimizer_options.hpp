#pragma once
// The tree-building options that `tsah optimize` and `tsah evaluate` share (representative and
// evaluation frames, cost constants, leaf size, which optimizer and how it runs), registered on a
// subcommand in one place and turned into one tsah::BaselineConfig.
#include <cstdint>
#include <functional>
#include <string>

#include "tsah/baselines.hpp"

namespace CLI {
class App;
}

namespace tsah::cli {

struct OptimizerOptions {
  uint32_t frames = 5;       // representative frames
  uint32_t evalFrames = 50;  // evaluation frames
  uint32_t maxLeaf = 8;
  float ct = 3.0f, ci = 2.0f;
  std::string optimizer = "sequential";  // sequential | parallel
  std::string selection = "mh";        // node selection of the sequential optimizer
  uint64_t seed = 1;
  double timeLimit = 0.0;
  double minImprovement = InsertionOptimizer::Config{}.minImprovement;
  unsigned threads = 0;  // 0: all cores

  // Adds --frames, --eval-frames, --max-leaf, --ct, --ci, --optimizer, --selection, --seed,
  // --time-limit, --min-improvement and --threads to a subcommand.
  void addTo(CLI::App& command);
  // The builders' settings; progress messages go to `progress`.
  BaselineConfig baselineConfig(std::function<void(const std::string&)> progress) const;
};

}  // namespace tsah::cli
