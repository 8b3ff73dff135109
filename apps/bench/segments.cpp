#include "bench/segments.hpp"

#include <algorithm>
#include <chrono>

#include "animation_frames.hpp"

namespace tsah::bench {

namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

double sum(std::span<const double> v) {
  double s = 0.0;
  for (double x : v) s += x;
  return s;
}

nlohmann::json modeJson(const SegmentationResult& r, std::span<const double> rebuild) {
  std::vector<double> splits;
  for (std::size_t s = 1; s < r.parts.size(); ++s) splits.push_back(r.parts[s].start);
  nlohmann::json j = {{"trees", r.trees.size()},
                      {"split_times", splits},
                      {"methods", r.methods},
                      {"build_s", sum(r.buildSeconds)},
                      {"search_s", r.searchSeconds},
                      {"candidate_trees", r.treesBuilt},
                      {"average", r.average},
                      {"maximum", r.maximum},
                      {"per_frame", r.costs}};
  if (rebuild.size() == r.costs.size() && !rebuild.empty()) {
    double peak = 0.0;
    for (std::size_t f = 0; f < r.costs.size(); ++f) peak = std::max(peak, r.costs[f] / rebuild[f]);
    j["peak_ratio_to_rebuild"] = peak;
    j["average_ratio_to_rebuild"] = sum(r.costs) / sum(rebuild);
  }
  return j;
}

}  // namespace

SegmentRuns runSegmentExperiment(const anim::Animation& a, const SegmentExperiment& e, const BaselineConfig& config,
                                 nlohmann::json& out, const std::function<void(const std::string&)>& say) {
  SegmentRuns runs;
  const Timeline timeline = tsah::cli::animationTimeline(a);
  SegmentationConfig sc;
  sc.method = MethodSpec::parse("tsah0");
  sc.representativeFrames = e.frames;
  sc.evaluationFrames = e.evalFrames;
  sc.baseline = config;
  nlohmann::json j;
  j["count"] = e.count;
  j["one_tree"] = {{"build_s", e.oneTreeBuildSeconds},
                   {"average", e.oneTreeCosts.empty() ? 0.0 : sum(e.oneTreeCosts) / double(e.oneTreeCosts.size())},
                   {"maximum", e.oneTreeCosts.empty() ? 0.0 : *std::max_element(e.oneTreeCosts.begin(), e.oneTreeCosts.end())}};
  if (e.rebuildCosts.size() == e.oneTreeCosts.size() && !e.rebuildCosts.empty()) {
    double peak = 0.0;
    for (std::size_t f = 0; f < e.rebuildCosts.size(); ++f) peak = std::max(peak, e.oneTreeCosts[f] / e.rebuildCosts[f]);
    j["one_tree"]["peak_ratio_to_rebuild"] = peak;
    j["one_tree"]["average_ratio_to_rebuild"] = sum(e.oneTreeCosts) / sum(e.rebuildCosts);
  }
  if (e.count > 1) {
    say("T-SAH k=0 for " + std::to_string(e.count) + " equal-time parts");
    auto start = std::chrono::steady_clock::now();
    runs.equal = evaluateParts(timeline, equalTimeRanges(a.startTime(), a.endTime(), e.count), sc);
    j["wall_s"] = secondsSince(start);
    nlohmann::json parts = nlohmann::json::array();
    for (std::size_t s = 0; s < runs.equal.trees.size(); ++s)
      parts.push_back({{"time_start", runs.equal.parts[s].start},
                       {"time_end", runs.equal.parts[s].end},
                       {"build_s", runs.equal.buildSeconds[s]},
                       {"nodes", runs.equal.trees[s].nodeCount()},
                       {"optimized_cost", runs.equal.optimizations[s].finalCost}});
    j["parts"] = parts;
    j["build_s"] = sum(runs.equal.buildSeconds);
    j["k_trees"] = modeJson(runs.equal, e.rebuildCosts);

    say("count mode: split points for " + std::to_string(e.count) + " trees");
    sc.mode = SegmentationConfig::Mode::Count;
    sc.count = e.count;
    runs.count = segmentTimeline(timeline, sc);
    j["count_mode"] = modeJson(runs.count, e.rebuildCosts);
  }
  if (e.budget > 0.0) {
    say("budget mode: the fewest trees within " + std::to_string(e.budget) + "x SAH-rebuild");
    sc.mode = SegmentationConfig::Mode::Budget;
    sc.budget = e.budget;
    sc.budgetRelative = true;
    sc.referenceCosts = e.rebuildCosts;  // exact: SAH-rebuild at every evaluation frame
    runs.budget = segmentTimeline(timeline, sc);
    j["budget_mode"] = modeJson(runs.budget, e.rebuildCosts);
    j["budget_mode"]["budget"] = e.budget;
    j["budget_mode"]["met"] = runs.budget.budgetMet;
  }
  out = j;
  return runs;
}

}  // namespace tsah::bench
