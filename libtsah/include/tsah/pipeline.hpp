#pragma once
// The toolkit's steps on a whole anim::Animation, as `tsah optimize`, `tsah evaluate` and the
// Python module run them: representative frames, one optimized tree with its .tbvh header, a tree
// set (`tsah optimize --segments`), costs
// over evaluation frames, the paper's Table 1, and batches of rays traced on the CPU runtime.
//
// This is the one place where libtsah meets an Animation; the builders themselves (baselines.hpp)
// still take primitive boxes. Public API: see docs/api.md.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/core/objective.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/optimize/segmentation.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/base/work_dealer.hpp"

namespace tsah {

// The options of `tsah optimize` / `tsah evaluate`, with the command line's defaults.
struct TreeOptions {
  Method method = Method::TSah;  // tsah, sah0 or sahstar (rebuild is no single tree)
  Objective objective;           // k (of method tsah), cT, cI, largest leaf after collapse
  uint32_t frames = 5;           // representative frames, uniform in time
  OptimizerKind optimizer = OptimizerKind::Sequential;  // the paper's insertion, or parallel reinsertion
  Selection selection = Selection::MetropolisHastings;  // node selection of the sequential optimizer
  uint64_t seed = 1;
  double timeLimit = 0.0;        // seconds per optimization, 0: none
  double minImprovement = InsertionOptimizer::Config{}.minImprovement;
  unsigned threads = 0;          // 0: all cores
  bool binnedInitialTree = false;  // BaselineConfig::binnedInitialTree
  // Cpu, or Cuda: every optimization by the GPU parallel reinsertion optimizer, which the caller
  // provides as gpuOptimizer (libtsah has no CUDA code; baselineConfig throws without it).
  Device device = Device::Cpu;
  TreeOptimizerFunction gpuOptimizer;
  std::function<void(const std::string&)> progress;  // optional progress messages
  // Optional: called after every batch (round) of every T-SAH optimization with its cost (the
  // history of InsertionOptimizer::Result as it grows); from the optimizing thread (with a tree
  // set's WorkDealer, from each worker's).
  std::function<void(const InsertionOptimizer::BatchRecord&)> batchProgress;
  // Optional cancel check, polled by every optimization (InsertionOptimizer::Config::cancelled)
  // and between trees: once it returns true the call throws tsah::Cancelled within a batch (32
  // steps) or a round. Must be cheap and thread-safe (an atomic flag).
  std::function<bool()> cancelled;

  // The limits of the command line's --frames, --eval-frames and --time-limit, and of Python's
  // frames, eval_frames and time_limit: one place for both.
  static constexpr uint32_t kMaxFrames = 1000;
  static constexpr uint32_t kMaxEvalFrames = 100000;

  // The method with the objective's k (T-SAH) or 0 (the others).
  MethodSpec methodSpec() const;
  // Throws tsah::ConfigError naming the field (frames, time_limit, min_improvement, or the
  // objective's) unless 1 <= frames <= kMaxFrames, timeLimit is finite and >= 0, minImprovement
  // is in [0, 1] and the objective is valid.
  void validate() const;
  // The builders' settings (objective, optimizer selection/seed/limits, threads, progress). Throws
  // tsah::ConfigError for invalid options (validate), or device Cuda without a gpuOptimizer (a build
  // without CUDA).
  BaselineConfig baselineConfig() const;
};

// Throws tsah::ConfigError ("eval_frames: ...") unless 1 <= evalFrames <= TreeOptions::kMaxEvalFrames.
void checkEvalFrames(uint32_t evalFrames);

// Throws tsah::ConfigError naming the first bad ray ("rays: ray 3: ...") when an origin or a
// direction is not finite, a direction is zero, tmin is not finite or negative, or tmax is NaN
// (a NaN ray makes traversal visit every node).
void checkRays(std::span<const Ray> rays);
// What checkRays says of one ray ("direction is zero"), or null when it can be traced.
const char* rayProblem(const Ray& ray);

// Frames of `animation` at each of `times` as a lazily filled FrameSource (triangle boxes). The
// animation must outlive the source.
FrameSource animationFrames(const anim::Animation& animation, std::vector<double> times);

// The animation as the segmentation sees it (triangle boxes at any time); must outlive the result.
Timeline animationTimeline(const anim::Animation& animation);

// `requested` for an animation, 1 for a static input (one keyframe: more frames would repeat it).
uint32_t framesFor(const anim::Animation& animation, uint32_t requested);

// The triangle boxes of framesFor(animation, frames) representative frames.
PrimitiveBoxes representativeBoxes(const anim::Animation& animation, uint32_t frames);

// The .tbvh header of a tree built with `options` for `animation` over [timeStart, timeEnd].
BvhBuildInfo treeBuildInfo(const TreeOptions& options, const anim::Animation& animation, uint32_t frames,
                           double buildSeconds, double timeStart, double timeEnd);

struct OptimizedTree {
  Bvh bvh;                                  // boxes for every representative frame
  BvhBuildInfo info;                        // what saveBvhFile writes into the header
  InsertionOptimizer::Result optimization;  // T-SAH only: costs and batch history (bvh left empty)
};

// One tree for the whole animation, exactly as `tsah optimize` builds it (same seed, same tree).
// Throws tsah::DataError when the animation has no triangles, tsah::ConfigError for method
// SahRebuild (no single tree) or an invalid objective.
OptimizedTree optimizeAnimation(const anim::Animation& animation, const TreeOptions& options);

// What `tsah optimize --segments K|auto` does (docs/segmentation.md): the options of each tree,
// and how the animation is split.
struct TreeSetOptions {
  TreeOptions tree;             // how each tree is built (method, k, frames, optimizer, seed, ...)
  uint32_t evalFrames = 50;     // where costs are measured, uniform over the animation (>= 2)
  uint32_t segments = 0;        // K in 1..kMaxSegments: count mode, K trees; 0: auto (budget mode)
  double budget = 0.0;          // auto: every frame within this factor (>= 1) of a per-frame
                                //   optimized SAH tree's cost; 0 with budgetCost 0: 1.05
  double budgetCost = 0.0;      // auto: an absolute bound on every frame's cost instead (> 0)
  double overlap = 0.0;         // seconds shared by consecutive trees (>= 0)
  uint32_t referenceFrames = SegmentationConfig{}.referenceFrames;  // relative budget's reference trees
  uint32_t maxTrees = SegmentationConfig{}.maxTrees;  // auto: at most this many trees (1..kTbvhMaxTrees)
  bool reproducible = false;    // every build time recorded as 0: the same bytes on every run
  WorkDealer* dealer = nullptr; // who builds the candidate trees (SegmentationConfig::dealer)

  static constexpr uint32_t kMaxSegments = 1000;
  // Throws tsah::ConfigError naming the field (segments, eval_frames, budget, budget_cost,
  // overlap, max_trees, or the tree options') for a value out of range or budgets given together
  // (or a budget with a count).
  void validate() const;
};

struct OptimizedTreeSet {
  std::vector<Bvh> trees;              // one per part, boxes for its representative frames
  std::vector<BvhBuildInfo> builds;    // each tree's header, its time range the tree's build range
  std::vector<TimeRange> ranges;       // the build ranges (what the file stores)
  TreeSetInfo info;                    // segmentation, overlap, budget
  SegmentationResult search;           // parts, costs per evaluation frame, budget (trees moved out)

  // The set as the runtimes take it (CpuRuntime, GpuRuntime; what loadTreeSetFile returns).
  TreeSet treeSet() const;
  // The .tbvh set file (version 2), as `tsah optimize --segments` writes it.
  std::vector<uint8_t> encode() const;
  void save(const std::string& path) const;  // atomic
};

// A tree set for the whole animation, exactly as `tsah optimize --segments` builds it (same seed,
// same trees, same file bytes with `reproducible`). Throws tsah::ConfigError for invalid options
// (TreeSetOptions::validate, TreeOptions::validate), tsah::DataError when the animation has no
// triangles or only one keyframe, tsah::Cancelled when options.tree.cancelled says so.
OptimizedTreeSet optimizeTreeSet(const anim::Animation& animation, const TreeSetOptions& options);

// Eq. 1 at framesFor(animation, evalFrames) times uniform over the animation, each with the tree of
// the set that its time selects (TreeSet::treeAt), refitted to it. Throws as evaluateAnimation.
std::vector<double> evaluateTreeSet(const TreeSet& set, const anim::Animation& animation, uint32_t evalFrames,
                                    const CostModel& cost = {}, unsigned threads = 0);

// Eq. 1 at framesFor(animation, evalFrames) times uniform over the animation, the tree refitted to each.
// Throws tsah::ConfigError for evalFrames out of range (checkEvalFrames) or an invalid cost model.
std::vector<double> evaluateAnimation(const Bvh& bvh, const anim::Animation& animation, uint32_t evalFrames,
                                      const CostModel& cost = {}, unsigned threads = 0);

// The paper's Table 1 for one animation, as `tsah evaluate` computes it.
std::vector<MethodResult> compareOnAnimation(const anim::Animation& animation, std::span<const MethodSpec> methods,
                                             const TreeOptions& options, uint32_t evalFrames);

// Throws tsah::DataError with one clear line ("BVH was not built for ANIMATION: ...") when the animation
// is not the one the tree was built for (triangle count, vertex count or topology hash differ).
void checkTreeMatchesAnimation(const BvhBuildInfo& info, const std::string& bvhPath, const anim::Animation& animation,
                               const std::string& animationPath);

// Closest hits and occlusion of a batch of rays against the runtime's current frame, in the
// runtime's layout (CpuRuntime::closestHit / anyHit: binary, or the SIMD kernels of bvh4/bvh8), on
// the runtime's threads; results in ray order. times: empty, or one shutter fraction per ray
// (CpuRuntime::closestHit(ray, time); tsah::ConfigError when the counts differ).
std::vector<Hit> closestHits(const CpuRuntime& runtime, std::span<const Ray> rays,
                             std::span<const float> times = {});
std::vector<uint8_t> anyHits(const CpuRuntime& runtime, std::span<const Ray> rays,
                             std::span<const float> times = {});

// A batch of rays as flat arrays (numpy's layout): ray i has origin origins[3i..3i+2], direction
// directions[3i..3i+2], tmin[i] and tmax[i]; a tmin or tmax of one value holds for every ray.
struct RayArrays {
  std::span<const float> origins, directions;  // 3 floats per ray each
  std::span<const float> tmin, tmax;          // one per ray, or one for all
  std::size_t size() const { return origins.size() / 3; }
  Ray at(std::size_t i) const {
    return {{origins[3 * i], origins[3 * i + 1], origins[3 * i + 2]}, tmin.size() == 1 ? tmin[0] : tmin[i],
            {directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]}, tmax.size() == 1 ? tmax[0] : tmax[i]};
  }
};

// closestHits / anyHits of rays given as arrays, written into hits / occluded (one per ray, the
// caller's memory: nothing is allocated). Each ray is made, checked (checkRays) and traced in the
// same task, so the batch costs what a batch of Ray structs costs. A ray that hits nothing gets
// t = inf, u = v = 0, tri = kNoHit; occluded[i] is 1 or 0. Throws tsah::ConfigError when the array
// sizes disagree (origins and directions of 3 floats per ray, hits the ray count, tmin and tmax 1
// or the ray count) or, naming the first one, when a ray cannot be traced (checkRays); after a bad
// ray the contents of hits / occluded are unspecified.
void closestHits(const CpuRuntime& runtime, const RayArrays& rays, std::span<Hit> hits);
void anyHits(const CpuRuntime& runtime, const RayArrays& rays, std::span<uint8_t> occluded);

// Motion blur (docs/motion-blur.md): the shutter of a traced frame as a fraction of the frame
// interval, centered on the frame's time or opening at it.
struct Shutter {
  double fraction = 0.0;  // in [0, 1]; 0: the instant
  enum class Mode { Centered, Open } mode = Mode::Centered;
};
// [open, close] of the frame at `time` for frame interval `interval`, clamped to the animation's
// time range. Throws tsah::ConfigError for a fraction outside [0, 1] or a negative interval.
std::pair<double, double> shutterInterval(const anim::Animation& animation, double time, double interval,
                                          const Shutter& shutter);
// The same clamped to [start, end] (a scene's time range: SceneSources::start, end).
std::pair<double, double> shutterInterval(double start, double end, double time, double interval,
                                          const Shutter& shutter);
// The shutter [open, close] cut where a tree set hands over (switchTime strictly inside it, with a
// shutter fraction strictly between 0, the previous cut and 1 in float): per stretch its tree
// (treeIndexAt of its start: rays in [open, switch) take the tree before the switch, from the
// switch on the one after), its key times (the stretch's ends and motion::shutterKeys' keys inside
// it; a keyframe whose fraction equals a cut's is left out: the cut is that key) and their
// fractions of the whole shutter (CpuRuntime::ShutterPart's key times). ranges empty or one: one
// stretch of tree 0. open == close: one key.
struct ShutterStretch {
  uint32_t tree = 0;
  std::vector<double> keys;
  std::vector<float> fractions;
};
std::vector<ShutterStretch> shutterStretches(std::span<const double> keyframeTimes, double open, double close,
                                             std::span<const TimeRange> ranges);
// Refits the runtime over [open, close] of the animation: the positions at every key of
// motion::shutterKeys (update() when open == close); a tree set by the tree of each ray's time, one
// part per shutterStretches' stretch.
void updateShutter(CpuRuntime& runtime, const anim::Animation& animation, double open, double close);

}  // namespace tsah
