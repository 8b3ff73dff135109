// The top-level trees of a two-level structure: one T-SAH TLAS over the scene's frames, or one per
// part of its time (TlasOptions), and the cost of the TLAS used at each scene frame.
#include <algorithm>
#include <chrono>
#include <span>
#include <cmath>
#include <limits>
#include <map>

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

namespace {

// Part boundaries as scene-frame indices: bounds[0] = 0 < bounds[1] < ... < bounds[parts] = the last
// frame; part s holds the frames bounds[s] .. bounds[s + 1].
std::vector<uint32_t> evenBoundaries(uint32_t frames, uint32_t parts) {
  parts = std::max(1u, std::min(parts, frames > 1 ? frames - 1 : 1u));
  std::vector<uint32_t> bounds(parts + 1);
  // The intervals between frames shared as evenly as they divide.
  for (uint32_t b = 0; b <= parts; ++b) bounds[b] = uint32_t(std::size_t(b) * (frames > 1 ? frames - 1 : 0) / parts);
  return bounds;
}

// The time ranges of the parts between `bounds`: from a part's first frame to its last, the
// scene's start and end at the ends.
std::vector<TimeRange> rangesOf(std::span<const uint32_t> bounds, std::span<const double> frameTimes, double start,
                                double end) {
  std::vector<TimeRange> ranges;
  for (std::size_t s = 0; s + 1 < bounds.size(); ++s)
    ranges.push_back({s == 0 ? start : frameTimes[bounds[s]], s + 2 == bounds.size() ? end : frameTimes[bounds[s + 1]]});
  return ranges;
}

}  // namespace

PrimitiveBoxes frameSlice(const PrimitiveBoxes& boxes, uint32_t first, uint32_t count) {
  PrimitiveBoxes out;
  out.frameCount = count;
  out.primCount = boxes.primCount;
  const auto begin = boxes.boxes.begin() + std::ptrdiff_t(std::size_t(first) * boxes.primCount);
  out.boxes.assign(begin, begin + std::ptrdiff_t(std::size_t(count) * boxes.primCount));
  return out;
}

namespace {

// The TLAS of one time range: T-SAH over the scene frames inside it, with its header.
TlasTree buildTree(const anim::SceneSources& scene, const TwoLevelScene& out, const TimeRange& range,
                   const TreeOptions& options, const BaselineConfig& config) {
  TlasTree tree;
  tree.range = range;
  std::tie(tree.firstFrame, tree.frameCount) = framesInside(out.frameTimes, tree.range);
  const PrimitiveBoxes boxes = frameSlice(out.instanceBoxes, tree.firstFrame, tree.frameCount);
  const auto start = std::chrono::steady_clock::now();
  tree.bvh = buildTSah(boxes, options.objective.k, config);
  const double seconds = secondsSince(start);
  requireValid(tree.bvh, boxes,
               scene.description.file + ": TLAS of frames " + std::to_string(tree.firstFrame) + " to " +
                   std::to_string(tree.firstFrame + tree.frameCount - 1));
  // Its header: the options of the first source's, counts and hash of the instance table.
  tree.info = treeBuildInfo(options, *scene.sources[0], tree.frameCount, seconds, tree.range.start, tree.range.end);
  tree.info.representativeFrames = tree.frameCount;
  tree.info.triangleCount = uint32_t(scene.instances.size());
  tree.info.vertexCount = 0;
  tree.info.topologyHash = instanceTableHash(scene);
  return tree;
}

// One TLAS per range, concurrently (each the same however the threads are shared).
std::vector<TlasTree> buildTrees(const anim::SceneSources& scene, const TwoLevelScene& out,
                                 std::span<const TimeRange> ranges, const TreeOptions& options,
                                 const BaselineConfig& config) {
  std::vector<TlasTree> trees(ranges.size());
  forEachConcurrently(trees.size(), [&](std::size_t s) { trees[s] = buildTree(scene, out, ranges[s], options, config); });
  return trees;
}

// Moves the inner boundaries of a TLAS set's parts (evenBoundaries' form) to lower the average
// Eq. 1 cost over the scene frames. A part is judged by a stand-in for its T-SAH tree, cheap enough
// to try many: a sweep-SAH TLAS over the instance boxes of its middle frame, refitted to each of
// its frames. Each boundary in turn, between its neighbours: a step of a quarter of its room is
// tried both ways and halved when neither move lowers the summed cost of the frames the two parts
// own (a frame on a boundary belongs to the later part, tlasAt's rule), down to one frame; a
// lowering move is kept and tried again. At most kPasses passes over the boundaries, fewer when one
// moves nothing. Each part's stand-in is built once, however often the search looks at it.
class BoundarySearch {
 public:
  static constexpr int kPasses = 3;
  // Less gain on the stand-ins is not worth building the moved parts' trees for.
  static constexpr double kMinGain = 0.01;

  explicit BoundarySearch(const TwoLevelScene& out) : out_(out), last_(uint32_t(out.frameTimes.size()) - 1) {}

  // The searched boundaries, or `bounds` itself when they lower the stand-ins' cost by less than
  // kMinGain.
  std::vector<uint32_t> run(std::vector<uint32_t> bounds) {
    const std::vector<uint32_t> from = bounds;
    for (int pass = 0; pass < kPasses; ++pass) {
      bool moved = false;
      for (std::size_t b = 1; b + 1 < bounds.size(); ++b) moved |= moveBoundary(bounds[b - 1], bounds[b], bounds[b + 1]);
      if (!moved) break;
    }
    return total(bounds) < (1.0 - kMinGain) * total(from) ? bounds : from;
  }

 private:
  // Eq. 1 of the stand-in summed over the frames the part first .. last owns: its last frame is the
  // next part's first, except at the scene's end.
  double owned(uint32_t first, uint32_t last) {
    const auto [it, fresh] = owned_.try_emplace({first, last}, 0.0);
    if (!fresh) return it->second;
    const uint32_t count = last - first + 1, instances = out_.instanceBoxes.primCount;
    const std::span<const Aabb> middle(out_.instanceBoxes.boxes.data() + std::size_t(first + count / 2) * instances,
                                       instances);
    Bvh tree = rebuildTlas(middle, out_.objective);
    refit(tree, frameSlice(out_.instanceBoxes, first, count));
    const std::vector<double> costs = frameCosts(tree, out_.objective.cost);
    const uint32_t ownedEnd = last == last_ ? last + 1 : last;
    for (uint32_t f = first; f < ownedEnd; ++f) it->second += costs[f - first];
    return it->second;
  }

  double total(std::span<const uint32_t> bounds) {
    double sum = 0.0;
    for (std::size_t s = 0; s + 1 < bounds.size(); ++s) sum += owned(bounds[s], bounds[s + 1]);
    return sum;
  }

  // The boundary `at` between `before` and `after`; true when it moved.
  bool moveBoundary(uint32_t before, uint32_t& at, uint32_t after) {
    double current = owned(before, at) + owned(at, after);
    bool moved = false;
    for (uint32_t step = std::max(1u, (after - before) / 4); step >= 1;) {
      uint32_t best = at;
      for (const uint32_t c : {at - std::min(step, at - before), at + std::min(step, after - at)}) {
        if (c == before || c == after) continue;
        if (const double cost = owned(before, c) + owned(c, after); cost < current) current = cost, best = c;
      }
      if (best != at) {
        at = best;
        moved = true;
      } else {
        step /= 2;
      }
    }
    return moved;
  }

  const TwoLevelScene& out_;
  uint32_t last_;  // the scene's last frame
  std::map<std::pair<uint32_t, uint32_t>, double> owned_;
};

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
  const auto frames = uint32_t(out.frameTimes.size());
  const auto treesBetween = [&](std::span<const uint32_t> bounds) {
    return buildTrees(scene, out, rangesOf(bounds, out.frameTimes, scene.start, scene.end), options, config);
  };
  const auto meanCost = [&](std::span<const TlasTree> trees) {
    return temporalCost(frameCostsOf(trees, out.frameTimes, out.objective.cost), 0);
  };
  std::vector<uint32_t> bounds;  // out.tlases's parts
  double cost = std::numeric_limits<double>::infinity();
  if (tlas.trees != 0) {
    bounds = evenBoundaries(frames, tlas.trees);
    out.tlases = treesBetween(bounds);
  } else {
    const double bound = tlas.budget * rebuiltTlasCost(out);
    for (uint32_t parts = 1;; parts *= 2) {
      std::vector<uint32_t> trialBounds = evenBoundaries(frames, parts);
      std::vector<TlasTree> trial = treesBetween(trialBounds);
      const std::size_t trialParts = trial.size();
      const double trialCost = meanCost(trial);
      if (trialCost < cost) {
        cost = trialCost;
        bounds = std::move(trialBounds);
        out.tlases = std::move(trial);
      }
      // Fewer parts than asked: every interval between frames has its tree already.
      if (trialCost <= bound || trialParts < parts || parts * 2 > tlas.maxTrees) break;
    }
  }
  if (!tlas.searchBoundaries || out.tlases.size() < 2) return;
  // The search judges parts by stand-ins: the searched parts' own trees are kept only where they
  // cost less than the even parts' trees.
  const std::vector<uint32_t> searched = BoundarySearch(out).run(bounds);
  if (searched == bounds) return;
  std::vector<TlasTree> moved = treesBetween(searched);
  if (tlas.trees != 0) cost = meanCost(out.tlases);
  if (meanCost(moved) < cost) out.tlases = std::move(moved);
}

}  // namespace tsah
