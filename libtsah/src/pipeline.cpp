#include "tsah/pipeline.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah {

MethodSpec TreeOptions::methodSpec() const { return {method, method == Method::TSah ? objective.k : 0}; }

void TreeOptions::validate() const {
  if (frames < 1 || frames > kMaxFrames)
    throw ConfigError("frames: must be in 1.." + std::to_string(kMaxFrames) + ", not " + std::to_string(frames));
  if (!std::isfinite(timeLimit) || timeLimit < 0.0)
    throw ConfigError("time_limit: must be a finite number of seconds >= 0 (0: none), not " + std::to_string(timeLimit));
  if (!(minImprovement >= 0.0 && minImprovement <= 1.0))
    throw ConfigError("min_improvement: must be in [0, 1], not " + std::to_string(minImprovement));
  objective.validate("tree options");
}

void checkEvalFrames(uint32_t evalFrames) {
  if (evalFrames < 1 || evalFrames > TreeOptions::kMaxEvalFrames)
    throw ConfigError("eval_frames: must be in 1.." + std::to_string(TreeOptions::kMaxEvalFrames) + ", not " +
                      std::to_string(evalFrames));
}

const char* rayProblem(const Ray& r) {
  const auto finite = [](const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); };
  return !finite(r.org)                                        ? "origin is not finite"
         : !finite(r.dir)                                      ? "direction is not finite"
         : r.dir.x == 0.0f && r.dir.y == 0.0f && r.dir.z == 0.0f ? "direction is zero"
         : !std::isfinite(r.tmin) || r.tmin < 0.0f             ? "tmin must be finite and >= 0"
         : std::isnan(r.tmax)                                  ? "tmax is NaN"
                                                               : nullptr;
}

namespace {

[[noreturn]] void refuseRay(std::size_t index, const char* problem) {
  throw ConfigError("rays: ray " + std::to_string(index) + ": " + problem);
}

}  // namespace

void checkRays(std::span<const Ray> rays) {
  for (std::size_t i = 0; i < rays.size(); ++i)
    if (const char* problem = rayProblem(rays[i])) refuseRay(i, problem);
}

BaselineConfig TreeOptions::baselineConfig() const {
  validate();
  BaselineConfig config;
  config.objective = objective;
  config.threads = threads;
  config.binnedInitialTree = binnedInitialTree;
  config.optimizer.selection = selection;
  config.optimizer.seed = seed;
  config.optimizer.timeLimitSeconds = timeLimit;
  config.optimizer.minImprovement = minImprovement;
  config.optimizerKind = optimizer;
  config.parallel.threads = threads;
  config.progress = progress;
  config.optimizer.progress = batchProgress;
  config.optimizer.cancelled = cancelled;
  if (device == Device::Cuda) {
    if (!gpuOptimizer) throw ConfigError("device 'cuda': this build of tsah has no CUDA support");
    config.deviceOptimizer = gpuOptimizer;
  }
  return config;
}

FrameSource animationFrames(const anim::Animation& animation, std::vector<double> times) {
  FrameSource source;
  source.frameCount = static_cast<uint32_t>(times.size());
  source.primCount = animation.triangleCount();
  source.fill = [&animation, times = std::move(times)](uint32_t frame, std::span<Aabb> out) {
    const std::vector<float> positions = animation.positionsAt(times[frame]);
    triangleBoxes(animation.indices(), positions, out);
  };
  return source;
}

Timeline animationTimeline(const anim::Animation& animation) {
  return Timeline::fromTriangles(animation.indices(), animation.vertexCount(), animation.startTime(),
                                 animation.endTime(),
                                 [&animation](double t, std::span<float> out) { animation.positionsAt(t, out); });
}

uint32_t framesFor(const anim::Animation& animation, uint32_t requested) {
  return animation.keyframeCount() > 1 ? requested : 1u;
}

PrimitiveBoxes representativeBoxes(const anim::Animation& animation, uint32_t frames) {
  const uint32_t n = framesFor(animation, frames);
  PrimitiveBoxes rep;
  rep.frameCount = n;
  rep.primCount = animation.triangleCount();
  tsah::checkFitsInMemory(std::size_t(n) * rep.primCount * sizeof(Aabb), animation.name(),
                          std::to_string(n) + " representative frames");
  rep.boxes.resize(std::size_t(n) * rep.primCount);
  // One frame of positions at a time (the resampled animation is never held whole); its triangle
  // boxes in chunks on the arena's threads (each box depends on its triangle only).
  const std::vector<double> times = animation.uniformTimes(n);
  const std::span<const uint32_t> indices = animation.indices();
  constexpr std::size_t kChunk = 1 << 16;
  for (uint32_t f = 0; f < n; ++f) {
    const std::vector<float> positions = animation.positionsAt(times[f]);
    const std::span<Aabb> out = std::span<Aabb>(rep.boxes).subspan(std::size_t(f) * rep.primCount, rep.primCount);
    tbb::parallel_for(std::size_t(0), out.size(), kChunk, [&](std::size_t first) {
      const std::size_t count = std::min(kChunk, out.size() - first);
      triangleBoxes(indices.subspan(3 * first, 3 * count), positions, out.subspan(first, count));
    });
  }
  return rep;
}

BvhBuildInfo treeBuildInfo(const TreeOptions& options, const anim::Animation& animation, uint32_t frames,
                           double buildSeconds, double timeStart, double timeEnd) {
  const MethodSpec method = options.methodSpec();
  BvhBuildInfo info;
  info.method = name(method.method);
  // How nodes were chosen for optimization: none (SAH0), parallel (reinsertion) or the selection.
  info.selection = method.method == Method::Sah0                 ? "none"
                   : options.device == Device::Cuda               ? "parallel-cuda"
                   : options.optimizer == OptimizerKind::Parallel ? "parallel"
                                                                  : name(options.selection);
  info.objective = options.objective;
  info.objective.k = method.k;
  info.representativeFrames = frames;
  info.seed = options.seed;
  info.buildSeconds = buildSeconds;
  info.timeStart = timeStart;
  info.timeEnd = timeEnd;
  info.triangleCount = animation.triangleCount();
  info.vertexCount = animation.vertexCount();
  info.topologyHash = topologyHash(animation.indices());
  return info;
}

OptimizedTree optimizeAnimation(const anim::Animation& animation, const TreeOptions& options) {
  if (animation.triangleCount() == 0) throw tsah::DataError(animation.name() + ": no triangles to build a tree over");
  const MethodSpec method = options.methodSpec();
  const BaselineConfig config = options.baselineConfig();
  const uint32_t frames = framesFor(animation, options.frames);
  const PrimitiveBoxes rep = representativeBoxes(animation, frames);

  OptimizedTree tree;
  const auto start = std::chrono::steady_clock::now();
  tree.bvh = buildMethod(method, rep, config, &tree.optimization);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  tree.info = treeBuildInfo(options, animation, frames, seconds, animation.startTime(), animation.endTime());
  return tree;
}

void TreeSetOptions::validate() const {
  tree.validate();
  if (evalFrames < 2 || evalFrames > TreeOptions::kMaxEvalFrames)
    throw ConfigError("eval_frames: a tree set needs 2.." + std::to_string(TreeOptions::kMaxEvalFrames) +
                      " evaluation frames, not " + std::to_string(evalFrames));
  if (segments > kMaxSegments)
    throw ConfigError("segments: must be 1.." + std::to_string(kMaxSegments) + " trees or auto, not " +
                      std::to_string(segments));
  if (!(budget == 0.0 || (budget >= 1.0 && budget <= 100.0)))
    throw ConfigError("budget: must be a factor in [1, 100], not " + std::to_string(budget));
  if (!(budgetCost == 0.0 || (budgetCost > 0.0 && std::isfinite(budgetCost))))
    throw ConfigError("budget_cost: must be a finite cost > 0, not " + std::to_string(budgetCost));
  if (budget > 0.0 && budgetCost > 0.0) throw ConfigError("budget, budget_cost: give one of them, not both");
  if (segments != 0 && (budget > 0.0 || budgetCost > 0.0))
    throw ConfigError("budget: goes with segments auto (the fewest trees within the budget), not a count");
  if (!std::isfinite(overlap) || overlap < 0.0)
    throw ConfigError("overlap: must be a finite number of seconds >= 0, not " + std::to_string(overlap));
  if (maxTrees < 1 || maxTrees > kTbvhMaxTrees)
    throw ConfigError("max_trees: must be in 1.." + std::to_string(kTbvhMaxTrees) + ", not " + std::to_string(maxTrees));
}

TreeSet OptimizedTreeSet::treeSet() const {
  TreeSet set;
  set.info = info;
  set.ranges = ranges;
  set.builds = builds;
  for (const Bvh& tree : trees) set.trees.push_back(flattenBvh(tree));
  return set;
}

std::vector<uint8_t> OptimizedTreeSet::encode() const { return encodeTreeSetFile(trees, builds, ranges, info); }

void OptimizedTreeSet::save(const std::string& path) const { saveTreeSetFile(path, trees, builds, ranges, info); }

OptimizedTreeSet optimizeTreeSet(const anim::Animation& animation, const TreeSetOptions& options) {
  options.validate();
  if (animation.triangleCount() == 0) throw tsah::DataError(animation.name() + ": no triangles to build a tree over");
  if (animation.keyframeCount() <= 1)
    throw tsah::DataError(animation.name() + ": a tree set needs an animation (this input has one frame)");
  const MethodSpec method = options.tree.methodSpec();
  const uint32_t frames = framesFor(animation, options.tree.frames);
  SegmentationConfig sc;
  sc.method = method;
  sc.representativeFrames = frames;
  sc.evaluationFrames = options.evalFrames;
  sc.overlap = options.overlap;
  sc.baseline = options.tree.baselineConfig();
  sc.referenceFrames = options.referenceFrames;
  sc.maxTrees = options.maxTrees;
  sc.dealer = options.dealer;
  OptimizedTreeSet out;
  out.info.overlap = options.overlap;
  if (options.segments == 0) {
    sc.mode = SegmentationConfig::Mode::Budget;
    sc.budgetRelative = options.budgetCost == 0.0;
    sc.budget = sc.budgetRelative ? (options.budget > 0.0 ? options.budget : 1.05) : options.budgetCost;
    out.info.segmentation = "budget";
    out.info.budget = sc.budget;
    out.info.budgetRelative = sc.budgetRelative;
    if (options.tree.progress) options.tree.progress("budget segmentation");
  } else {
    sc.mode = SegmentationConfig::Mode::Count;
    sc.count = options.segments;
    out.info.segmentation = method.k > 0 ? "count-peak" : "count";
    if (options.tree.progress)
      options.tree.progress("choosing split points for " + std::to_string(options.segments) + " trees");
  }
  out.search = segmentTimeline(animationTimeline(animation), sc);
  SegmentationResult& r = out.search;
  for (uint32_t s = 0; s < r.trees.size(); ++s) {
    BvhBuildInfo info = treeBuildInfo(options.tree, animation, frames, options.reproducible ? 0.0 : r.buildSeconds[s],
                                      r.buildRanges[s].start, r.buildRanges[s].end);
    // A budget part too short to split further: an optimized SAH tree of one frame.
    if (r.methods[s] == "sah-frame") {
      info.method = "sah-frame";
      info.objective.k = 0;
      info.representativeFrames = 1;
    }
    out.builds.push_back(std::move(info));
  }
  out.trees = std::move(r.trees);
  r.trees.clear();
  out.ranges = r.buildRanges;
  return out;
}

std::vector<double> evaluateTreeSet(const TreeSet& set, const anim::Animation& animation, uint32_t evalFrames,
                                    const CostModel& cost, unsigned threads) {
  checkEvalFrames(evalFrames);
  Objective{0, cost, 1}.validate("costs");
  if (set.size() == 0 || set.trees[0].triangleCount() != animation.triangleCount())
    throw tsah::DataError(animation.name() + ": the tree set has " +
                          std::to_string(set.size() ? set.trees[0].triangleCount() : 0) + " triangles, the animation " +
                          std::to_string(animation.triangleCount()));
  const std::vector<double> times = animation.uniformTimes(framesFor(animation, evalFrames));
  std::vector<double> costs(times.size());
  // Each tree over the evaluation frames its time selects.
  for (uint32_t s = 0; s < set.size(); ++s) {
    std::vector<double> mine;
    std::vector<std::size_t> where;
    for (std::size_t f = 0; f < times.size(); ++f)
      if (set.treeAt(times[f]) == s) {
        mine.push_back(times[f]);
        where.push_back(f);
      }
    if (mine.empty()) continue;
    const std::vector<double> c = evaluateFrames(unflattenBvh(set.trees[s]), animationFrames(animation, std::move(mine)),
                                                 cost, threads);
    for (std::size_t i = 0; i < where.size(); ++i) costs[where[i]] = c[i];
  }
  return costs;
}

std::vector<double> evaluateAnimation(const Bvh& bvh, const anim::Animation& animation, uint32_t evalFrames,
                                      const CostModel& cost, unsigned threads) {
  checkEvalFrames(evalFrames);
  Objective{0, cost, 1}.validate("costs");
  if (bvh.primCount() != animation.triangleCount())
    throw tsah::DataError(animation.name() + ": the tree has " + std::to_string(bvh.primCount()) +
                          " triangles, the animation " + std::to_string(animation.triangleCount()));
  return evaluateFrames(bvh, animationFrames(animation, animation.uniformTimes(framesFor(animation, evalFrames))),
                        cost, threads);
}

std::vector<MethodResult> compareOnAnimation(const anim::Animation& animation, std::span<const MethodSpec> methods,
                                             const TreeOptions& options, uint32_t evalFrames) {
  checkEvalFrames(evalFrames);
  options.validate();
  if (animation.triangleCount() == 0) throw tsah::DataError(animation.name() + ": no triangles to build a tree over");
  const PrimitiveBoxes rep = representativeBoxes(animation, options.frames);
  return compareMethods(methods, rep,
                        animationFrames(animation, animation.uniformTimes(framesFor(animation, evalFrames))),
                        options.baselineConfig());
}

void checkTreeMatchesAnimation(const tsah::BvhBuildInfo& info, const std::string& bvhPath, const anim::Animation& a,
                               const std::string& animationPath) {
  auto fail = [&](const std::string& what) {
    throw tsah::DataError(bvhPath + " was not built for " + animationPath + ": " + what);
  };
  if (info.triangleCount != a.triangleCount())
    fail("the tree has " + std::to_string(info.triangleCount) + " triangles, the animation " +
         std::to_string(a.triangleCount()));
  if (info.vertexCount != a.vertexCount())
    fail("the tree was built for " + std::to_string(info.vertexCount) + " vertices, the animation has " +
         std::to_string(a.vertexCount()));
  const uint32_t hash = topologyHash(a.indices());
  if (info.topologyHash != hash) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "topology hash %08x, the animation's is %08x", info.topologyHash, hash);
    fail(std::string(buf) + " (same counts, different triangles)");
  }
}

namespace {

void checkTimes(std::span<const Ray> rays, std::span<const float> times) {
  if (!times.empty() && times.size() != rays.size())
    throw tsah::ConfigError("rays: " + std::to_string(times.size()) + " times for " + std::to_string(rays.size()) +
                            " rays");
}

}  // namespace

namespace {

constexpr std::size_t kRayGrain = 1024;  // rays per task of a batch: a chunk's rays and hits stay in cache

}  // namespace

std::vector<Hit> closestHits(const CpuRuntime& runtime, std::span<const Ray> rays, std::span<const float> times) {
  checkTimes(rays, times);
  std::vector<Hit> hits(rays.size());
  runtime.parallelFor(rays.size(), kRayGrain, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      hits[i] = times.empty() ? runtime.closestHit(rays[i]) : runtime.closestHit(rays[i], times[i]);
  });
  return hits;
}

std::vector<uint8_t> anyHits(const CpuRuntime& runtime, std::span<const Ray> rays, std::span<const float> times) {
  checkTimes(rays, times);
  std::vector<uint8_t> occluded(rays.size());
  runtime.parallelFor(rays.size(), kRayGrain, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      occluded[i] = (times.empty() ? runtime.anyHit(rays[i]) : runtime.anyHit(rays[i], times[i])) ? 1 : 0;
  });
  return occluded;
}

namespace {

void checkRayArrays(const RayArrays& rays, std::size_t results, const char* resultsName) {
  const std::size_t n = rays.size();
  auto fail = [](const std::string& what) { throw ConfigError("rays: " + what); };
  if (rays.origins.size() % 3 != 0)
    fail(std::to_string(rays.origins.size()) + " origin coordinates (3 per ray)");
  if (rays.directions.size() != rays.origins.size())
    fail(std::to_string(rays.directions.size()) + " direction coordinates for " + std::to_string(n) + " rays");
  for (const auto& [limit, name] : {std::pair{rays.tmin, "tmin"}, std::pair{rays.tmax, "tmax"}})
    if (limit.size() != n && limit.size() != 1)
      fail(std::to_string(limit.size()) + " " + name + " values for " + std::to_string(n) + " rays (1 or one per ray)");
  if (results != n) fail(std::to_string(results) + " " + resultsName + " for " + std::to_string(n) + " rays");
}

// trace(i, ray) for every ray of the arrays on the runtime's threads, each ray made and checked in
// the task that traces it. After a bad ray no task starts; the first bad ray is named.
template <class Trace>
void traceArrays(const CpuRuntime& runtime, const RayArrays& rays, const Trace& trace) {
  std::atomic<bool> bad{false};
  runtime.parallelFor(rays.size(), kRayGrain, [&](std::size_t begin, std::size_t end) {
    if (bad.load(std::memory_order_relaxed)) return;
    for (std::size_t i = begin; i < end; ++i) {
      const Ray ray = rays.at(i);
      if (rayProblem(ray)) {
        bad.store(true, std::memory_order_relaxed);
        return;
      }
      trace(i, ray);
    }
  });
  if (!bad.load()) return;
  for (std::size_t i = 0; i < rays.size(); ++i)
    if (const char* problem = rayProblem(rays.at(i))) refuseRay(i, problem);
}

}  // namespace

void closestHits(const CpuRuntime& runtime, const RayArrays& rays, std::span<Hit> hits) {
  checkRayArrays(rays, hits.size(), "hits");
  constexpr Hit kMiss{std::numeric_limits<float>::infinity(), 0.0f, 0.0f, kNoHit};
  traceArrays(runtime, rays, [&](std::size_t i, const Ray& ray) {
    const Hit hit = runtime.closestHit(ray);
    hits[i] = hit.valid() ? hit : kMiss;
  });
}

void anyHits(const CpuRuntime& runtime, const RayArrays& rays, std::span<uint8_t> occluded) {
  checkRayArrays(rays, occluded.size(), "occlusion flags");
  traceArrays(runtime, rays, [&](std::size_t i, const Ray& ray) { occluded[i] = runtime.anyHit(ray) ? 1 : 0; });
}

std::pair<double, double> shutterInterval(const anim::Animation& animation, double time, double interval,
                                          const Shutter& shutter) {
  return shutterInterval(animation.startTime(), animation.endTime(), time, interval, shutter);
}

std::pair<double, double> shutterInterval(double start, double end, double time, double interval,
                                          const Shutter& shutter) {
  if (!(shutter.fraction >= 0.0 && shutter.fraction <= 1.0))
    throw tsah::ConfigError("shutter: the fraction must lie in [0, 1], got " + std::to_string(shutter.fraction));
  if (!(interval >= 0.0))
    throw tsah::ConfigError("shutter: the frame interval must not be negative, got " + std::to_string(interval));
  const double length = shutter.fraction * interval;
  double open = shutter.mode == Shutter::Mode::Centered ? time - length / 2 : time;
  double close = open + length;
  open = std::clamp(open, start, end);
  close = std::clamp(close, start, end);
  return {open, close};
}

std::vector<ShutterStretch> shutterStretches(std::span<const double> keyframeTimes, double open, double close,
                                             std::span<const TimeRange> ranges) {
  const std::vector<double> keys = motion::shutterKeys(keyframeTimes, open, close);
  const std::vector<float> fractions = motion::keyFractions(keys);
  const auto treeAt = [&](double t) { return ranges.size() > 1 ? treeIndexAt(ranges, t) : 0u; };
  std::vector<ShutterStretch> out{{treeAt(open), {}, {}}};
  std::size_t k = 0;
  const auto takeKeysBelow = [&](float fraction) {
    for (; k < keys.size() && fractions[k] < fraction; ++k) {
      out.back().keys.push_back(keys[k]);
      out.back().fractions.push_back(fractions[k]);
    }
  };
  float previousCut = 0.0f;
  for (uint32_t s = 0; keys.size() > 1 && s + 1 < ranges.size(); ++s) {
    const double cut = switchTime(ranges, s);
    if (!(cut > open && cut < close)) continue;
    const auto fraction = static_cast<float>((cut - open) / (close - open));  // keyFractions' value
    if (!(fraction > previousCut && fraction < 1.0f)) continue;
    takeKeysBelow(fraction);
    if (k < keys.size() && fractions[k] == fraction) ++k;  // a keyframe at the cut's fraction: the cut is the key
    out.back().keys.push_back(cut);
    out.back().fractions.push_back(fraction);
    out.push_back({treeAt(cut), {cut}, {fraction}});
    previousCut = fraction;
  }
  takeKeysBelow(std::numeric_limits<float>::infinity());
  return out;
}

void updateShutter(CpuRuntime& runtime, const anim::Animation& animation, double open, double close) {
  const std::vector<ShutterStretch> stretches = shutterStretches(animation.times(), open, close, runtime.treeRanges());
  // The positions at every key, a cut's computed once: the key that ends a stretch starts the next.
  std::vector<std::vector<float>> positions;
  std::vector<std::vector<std::span<const float>>> spans(stretches.size());
  std::vector<CpuRuntime::ShutterPart> parts;
  for (const ShutterStretch& stretch : stretches)
    for (std::size_t k = &stretch == &stretches.front() ? 0 : 1; k < stretch.keys.size(); ++k)
      positions.push_back(animation.positionsAt(stretch.keys[k]));
  std::size_t next = 0;
  for (std::size_t p = 0; p < stretches.size(); ++p) {
    for (std::size_t k = 0; k < stretches[p].keys.size(); ++k)
      spans[p].push_back(p > 0 && k == 0 ? spans[p - 1].back() : std::span<const float>(positions[next++]));
    parts.push_back({stretches[p].tree, stretches[p].fractions, spans[p]});
  }
  runtime.updateShutter(parts);
}

}  // namespace tsah
