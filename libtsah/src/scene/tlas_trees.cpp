// The top-level trees of a two-level structure: one T-SAH TLAS over the scene's frames, or one per
// part of its time (TlasOptions), and the cost of the TLAS used at each scene frame.
#include <algorithm>
#include <chrono>
#include <span>
#include <cmath>
#include <limits>

#include "tsah/base/error.hpp"
#include "tsah/base/parallel_each.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/optimize/baselines.hpp"
#include "scene/two_level_parts.hpp"

namespace tsah {

void TlasOptions::validate() const {
  if (trees > kMaxTrees)
    throw ConfigError("tlas_trees: " + std::to_string(trees) + " is more than " + std::to_string(kMaxTrees));
  if (maxTrees == 0 || maxTrees > kMaxTrees)
    throw ConfigError("tlas_max_trees: " + std::to_string(maxTrees) + " is not in 1.." + std::to_string(kMaxTrees));
  if (!(std::isfinite(budget) && budget >= 1.0))
    throw ConfigError("tlas_budget: " + std::to_string(budget) + " is not a finite factor >= 1");
}

namespace {

// The tree of `sceneTime` among `trees` (treeIndexAt's rule).
uint32_t treeAt(std::span<const TlasTree> trees, double sceneTime) {
  if (trees.size() == 1) return 0;
  std::vector<TimeRange> ranges;
  for (const TlasTree& t : trees) ranges.push_back(t.range);
  return treeIndexAt(ranges, sceneTime);
}

// Eq. 1 at each of `frameTimes` of the tree used there.
std::vector<double> frameCostsOf(std::span<const TlasTree> trees, std::span<const double> frameTimes,
                                 const CostModel& model) {
  std::vector<std::vector<double>> perTree(trees.size());
  forEachConcurrently(perTree.size(), [&](std::size_t s) { perTree[s] = frameCosts(trees[s].bvh, model); });
  std::vector<double> costs(frameTimes.size());
  for (std::size_t f = 0; f < costs.size(); ++f) {
    const uint32_t s = treeAt(trees, frameTimes[f]);
    costs[f] = perTree[s][f - trees[s].firstFrame];
  }
  return costs;
}

}  // namespace

uint32_t TwoLevelScene::tlasAt(double sceneTime) const { return treeAt(tlases, sceneTime); }

std::pair<uint32_t, uint32_t> framesInside(std::span<const double> frameTimes, const TimeRange& range) {
  const auto first = std::lower_bound(frameTimes.begin(), frameTimes.end(), range.start);
  const auto end = std::upper_bound(frameTimes.begin(), frameTimes.end(), range.end);
  return {uint32_t(first - frameTimes.begin()), uint32_t(std::max(end, first) - first)};
}

std::vector<TimeRange> tlasPartRanges(std::span<const double> frameTimes, double start, double end, uint32_t parts) {
  const auto frames = uint32_t(frameTimes.size());
  parts = std::max(1u, std::min(parts, frames > 1 ? frames - 1 : 1u));
  std::vector<TimeRange> ranges(parts);
  // Boundaries at scene frames, the intervals between frames shared as evenly as they divide.
  for (uint32_t s = 0; s < parts; ++s) {
    const auto boundary = [&](uint32_t b) { return frameTimes[std::size_t(b) * (frames - 1) / parts]; };
    ranges[s].start = s == 0 ? start : boundary(s);
    ranges[s].end = s + 1 == parts ? end : boundary(s + 1);
  }
  return ranges;
}

PrimitiveBoxes frameSlice(const PrimitiveBoxes& boxes, uint32_t first, uint32_t count) {
  PrimitiveBoxes out;
  out.frameCount = count;
  out.primCount = boxes.primCount;
  const auto begin = boxes.boxes.begin() + std::ptrdiff_t(std::size_t(first) * boxes.primCount);
  out.boxes.assign(begin, begin + std::ptrdiff_t(std::size_t(count) * boxes.primCount));
  return out;
}

namespace {

// One TLAS per range, concurrently (each the same however the threads are shared).
std::vector<TlasTree> buildTrees(const anim::SceneSources& scene, const TwoLevelScene& out,
                                 std::span<const TimeRange> ranges, const TreeOptions& options,
                                 const BaselineConfig& config) {
  std::vector<TlasTree> trees(ranges.size());
  forEachConcurrently(trees.size(), [&](std::size_t s) {
    TlasTree& tree = trees[s];
    tree.range = ranges[s];
    std::tie(tree.firstFrame, tree.frameCount) = framesInside(out.frameTimes, tree.range);
    const PrimitiveBoxes boxes = frameSlice(out.instanceBoxes, tree.firstFrame, tree.frameCount);
    const auto start = std::chrono::steady_clock::now();
    tree.bvh = buildTSah(boxes, options.objective.k, config);
    const double seconds = secondsSince(start);
    requireValid(tree.bvh, boxes, scene.description.file + ": TLAS " + std::to_string(s));
    // Its header: the options of the first source's, counts and hash of the instance table.
    tree.info = treeBuildInfo(options, *scene.sources[0], tree.frameCount, seconds, tree.range.start, tree.range.end);
    tree.info.representativeFrames = tree.frameCount;
    tree.info.triangleCount = uint32_t(scene.instances.size());
    tree.info.vertexCount = 0;
    tree.info.topologyHash = instanceTableHash(scene);
  });
  return trees;
}

// The mean Eq. 1 cost over the scene's frames of a sweep-SAH TLAS rebuilt at each.
double rebuiltTlasCost(const TwoLevelScene& out) {
  const uint32_t count = out.instanceBoxes.primCount;
  std::vector<double> costs(out.frameTimes.size());
  forEachConcurrently(costs.size(), [&](std::size_t f) {
    const std::span<const Aabb> frame(out.instanceBoxes.boxes.data() + f * count, count);
    costs[f] = frameCosts(rebuildTlas(frame, out.objective), out.objective.cost)[0];
  });
  return temporalCost(costs, 0);
}

}  // namespace

std::vector<double> tlasFrameCosts(const TwoLevelScene& out) {
  return frameCostsOf(out.tlases, out.frameTimes, out.objective.cost);
}

void buildTlasTrees(const anim::SceneSources& scene, TwoLevelScene& out, const TreeOptions& options,
                    const TlasOptions& tlas) {
  // The TLAS is optimized on the CPU whatever the device: it has one leaf per instance, and its
  // objective covers every frame of its part (the GPU optimizer takes at most 16 representative frames).
  BaselineConfig config = options.baselineConfig();
  config.deviceOptimizer = nullptr;
  const auto rangesFor = [&](uint32_t parts) { return tlasPartRanges(out.frameTimes, scene.start, scene.end, parts); };
  if (tlas.trees != 0) {
    out.tlases = buildTrees(scene, out, rangesFor(tlas.trees), options, config);
    return;
  }
  const double bound = tlas.budget * rebuiltTlasCost(out);
  double best = std::numeric_limits<double>::infinity();
  for (uint32_t parts = 1;; parts *= 2) {
    const std::vector<TimeRange> ranges = rangesFor(parts);
    std::vector<TlasTree> trial = buildTrees(scene, out, ranges, options, config);
    const double cost = temporalCost(frameCostsOf(trial, out.frameTimes, out.objective.cost), 0);
    if (cost < best) {
      best = cost;
      out.tlases = std::move(trial);
    }
    // Fewer parts than asked: every interval between frames has its tree already.
    if (cost <= bound || ranges.size() < parts || parts * 2 > tlas.maxTrees) return;
  }
}

}  // namespace tsah
