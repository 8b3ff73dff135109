#pragma once
// The methods the paper compares (Section 6.1, Table 1), built and evaluated the same way.
//
//   sah0     sweep SAH on the first representative frame, refitted to the others
//   sahstar  best over time: one optimized SAH tree per representative frame, keeping the one with
//            the lowest average cost over the representative frames
//   rebuild  an optimized SAH tree for every evaluation frame (the lower bound; no single tree)
//   tsahK    sweep SAH on the first frame, then insertion optimization with the T-SAH cost of
//            exponent K over all representative frames (tsah0, tsah2, tsah4, ...)
//
// Every tree is collapsed to adaptive leaves (maxLeafSize; 1 keeps one primitive per leaf) with the
// cost of the frames it was built for, then evaluated by refitting it to each evaluation frame.
// The builders never see an animation: frames arrive as primitive boxes or triangle positions
// (tsah/pipeline.hpp is the glue from an anim::Animation).
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"

namespace tsah {

// The primitive boxes of a sequence of frames, produced on demand (evaluation frames can be many).
struct FrameSource {
  uint32_t frameCount = 0;
  uint32_t primCount = 0;
  // Fills `out` (primCount boxes, by primitive id) for one frame. Must be safe to call from
  // several threads at once.
  std::function<void(uint32_t frame, std::span<Aabb> out)> fill;

  // Frames of precomputed boxes; `boxes` must outlive the source.
  static FrameSource fromBoxes(const PrimitiveBoxes& boxes);
  // Triangles (3 indices each) over frameCount blocks of vertex positions (xyz floats); both spans
  // must outlive the source.
  static FrameSource fromTriangles(std::span<const uint32_t> indices, std::span<const float> positions,
                                   uint32_t frameCount);
};

struct MethodSpec {
  Method method = Method::TSah;
  int k = 0;  // T-SAH exponent

  // "sah0", "sahstar", "rebuild", "tsah<k>".
  std::string name() const;
  // Parses a name as above ("tsah" alone means tsah0); throws tsah::ConfigError otherwise and for
  // k > Objective::kMaxK (tsah17).
  static MethodSpec parse(const std::string& name);
};

// An optimizer run elsewhere (the GPU optimizer, which libtsah cannot call: the tsah program and
// the Python module set it from tsah_cuda): the same contract as optimizeTree.
using TreeOptimizerFunction = std::function<InsertionOptimizer::Result(
    Bvh bvh, const PrimitiveBoxes& prims, const InsertionOptimizer::Config& settings, const LeafCollapser* collapse)>;

struct BaselineConfig {
  // cT, cI and the largest leaf of the collapse after building (1 keeps one primitive per leaf).
  // Its k is each method's own (MethodSpec::k; 0 for SAH0, SAH*, SAH-rebuild).
  Objective objective;
  // Settings of every optimization (SAH*, SAH-rebuild, T-SAH), whichever optimizer runs it. Its
  // cost model and k are replaced by the objective's cost and the method's k; single-frame
  // optimizations get derived seeds.
  InsertionOptimizer::Config optimizer;
  OptimizerKind optimizerKind = OptimizerKind::Sequential;  // core/kinds.hpp
  ParallelReinsertionOptimizer::Parallel parallel;  // settings of the parallel optimizer (its threads)
  // When set, every optimization runs here instead (optimizerKind is then unused).
  TreeOptimizerFunction deviceOptimizer;
  unsigned threads = 0;  // worker threads for independent trees and frames; 0: all cores
  // Start from the multithreaded binned SAH tree instead of the sweep SAH tree (single-threaded:
  // most of the build time of a static object of millions of triangles optimized on the GPU).
  bool binnedInitialTree = false;
  // Progress messages (which method, which frame, optimizer batches). May be called from worker
  // threads, one call at a time.
  std::function<void(const std::string& message)> progress;
};

// Builders of the single-tree methods. rep: the representative frames. The result holds boxes for
// every representative frame. `details` (optional) receives the T-SAH optimizer's result (its
// history, costs; its bvh member is left empty).
Bvh buildSah0(const PrimitiveBoxes& rep, const BaselineConfig& config);
Bvh buildSahStar(const PrimitiveBoxes& rep, const BaselineConfig& config);
Bvh buildTSah(const PrimitiveBoxes& rep, int k, const BaselineConfig& config,
              InsertionOptimizer::Result* details = nullptr);
// Any single-tree method (throws tsah::ConfigError for SahRebuild, which builds many trees).
Bvh buildMethod(const MethodSpec& method, const PrimitiveBoxes& rep, const BaselineConfig& config,
                InsertionOptimizer::Result* details = nullptr);
// An optimized SAH tree for one frame (sweep SAH, insertion optimization, collapse), as SAH* and
// SAH-rebuild use it. frameCount = 1.
Bvh buildOptimizedSah(std::span<const Aabb> frame, const BaselineConfig& config, uint64_t seed);

// One optimization with the configured optimizer (config.optimizerKind), with `settings` (a copy
// of config.optimizer with the method's k and seed); with `collapse`, the result's tree collapsed
// by it (see InsertionOptimizer::optimize).
InsertionOptimizer::Result optimizeTree(Bvh bvh, const PrimitiveBoxes& prims, const InsertionOptimizer::Config& settings,
                                        const BaselineConfig& config, const LeafCollapser* collapse = nullptr);

// Eq. 1 per frame of `frames` after refitting the tree's topology to each of them.
std::vector<double> evaluateFrames(const Bvh& bvh, const FrameSource& frames, const CostModel& cost,
                                   unsigned threads = 0);

struct MethodResult {
  std::string name;
  // Time to build on one core (rebuild: all of its trees; SAH*: all candidates): the methods run
  // side by side on the worker threads, each piece measured as the CPU time of its thread, so the
  // figure does not depend on the thread count or on other load on the machine.
  double buildSeconds = 0.0;
  double average = 0.0, maximum = 0.0;
  std::vector<double> perFrame;  // cost at every evaluation frame
};

// Builds every method and evaluates it on the evaluation frames (the paper's Table 1). The
// independent trees of all methods are built in parallel (config.threads); the results do not
// depend on the thread count. Progress goes to config.progress only (config.optimizer.progress is
// not called).
std::vector<MethodResult> compareMethods(std::span<const MethodSpec> methods, const PrimitiveBoxes& rep,
                                         const FrameSource& evaluation, const BaselineConfig& config);

}  // namespace tsah
