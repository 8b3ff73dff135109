#pragma once
// The bench's segmentation experiment (tsah/segmentation.hpp does the work): for one scene, T-SAH
// k=0 with K equal-time parts (the paper's BART Museum*), the count mode with the same K (split
// points chosen by the library) and the budget mode (the fewest trees keeping every evaluation
// frame within budget x the SAH-rebuild cost of Table 1), against one tree and the per-frame
// rebuild: number of trees, split times, build and search time, average and peak cost.
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/optimize/segmentation.hpp"

namespace tsah::bench {

struct SegmentRuns {
  SegmentationResult equal, count, budget;  // empty (no trees) when skipped
};

struct SegmentExperiment {
  uint32_t count = 3;                // K of the equal-time parts and of the count mode (1: skip both)
  double budget = 1.05;              // the budget mode's factor (0: skip)
  uint32_t frames = 5;               // representative frames per part
  uint32_t evalFrames = 50;
  std::vector<double> rebuildCosts;  // SAH-rebuild at each evaluation frame: the budget's reference
  std::vector<double> oneTreeCosts;  // the single T-SAH k=0 tree at each evaluation frame
  double oneTreeBuildSeconds = 0.0;
};

// Runs what `e` asks for; writes the "segments" JSON of the scene into `out` (keys: count, parts,
// build_s, wall_s, one_tree, k_trees for the equal-time parts; count_mode and budget_mode with
// trees, split_times, build_s, search_s, candidate_trees, average, maximum, per_frame and, for the
// budget, ratios to the rebuild).
SegmentRuns runSegmentExperiment(const anim::Animation& animation, const SegmentExperiment& e,
                                 const BaselineConfig& config, nlohmann::json& out,
                                 const std::function<void(const std::string&)>& say);

// The count mode alone: K T-SAH k=0 trees with split points chosen by the library (what
// `tsah optimize --segments K` makes), e.g. the toolkit's tree set in the Embree comparison.
SegmentationResult countModeTrees(const anim::Animation& animation, uint32_t count, uint32_t frames,
                                  uint32_t evalFrames, const BaselineConfig& config);

}  // namespace tsah::bench
