#pragma once
// Segmentation: where to split an animation into parts, one tree per part (docs/segmentation.md).
//
//   count mode   K trees; the split points are moved to minimize the average cost over the
//                evaluation frames (the peak cost when the trees' T-SAH exponent k > 0), starting
//                from K equal-time parts and accepting only improvements, so the result is never
//                worse than equal-time parts on those frames.
//   budget mode  the fewest trees such that every evaluation frame's cost stays within a bound:
//                budget x (a per-frame optimized SAH tree's cost, estimated on a sample of frames
//                and interpolated linearly in between) or an absolute cost. Greedy: each part is
//                extended as far as the bound allows (binary search over the evaluation frames),
//                then the same local search as the count mode lowers the worst cost/bound ratio
//                with the count fixed. A part of one evaluation interval whose tree still misses
//                the bound gets a per-frame optimized SAH tree of its frame instead.
//
// Candidate split points are evaluation frames (and, in count mode, the equal-time boundaries).
// Every candidate part's tree and its costs on the evaluation frames are cached, so a part is
// built once however often the search considers it. Deterministic for a seed.
//
// With a WorkDealer (SegmentationConfig::dealer) the candidate trees and the reference trees are
// built by its workers (threads owning a GPU each, MPI ranks): every process runs the same search,
// and where it will need several candidates (both moves of a split point, the next levels of a
// binary search) it builds them at once, one per worker, possibly some it will not use. The search
// takes the same decisions from the same trees, so the result is the same as without a dealer;
// only treesBuilt (and the time) differ.
// libtsah never sees an animation: the caller provides primitive boxes at any time (Timeline).
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "tsah/base/work_dealer.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/io/tree_set.hpp"

namespace tsah {

// An animation as the segmentation sees it: the boxes of its primitives at any time.
struct Timeline {
  double start = 0.0, end = 0.0;
  uint32_t primCount = 0;
  // Fills `out` (primCount boxes, by primitive id) at `time`. Must be safe to call from several
  // threads at once.
  std::function<void(double time, std::span<Aabb> out)> boxesAt;

  // Triangles (3 indices each, the animation's topology) whose vertices (vertexCount xyz) are given
  // at any time by positionsAt, which must be thread-safe; the references must outlive the result.
  static Timeline fromTriangles(std::span<const uint32_t> indices, uint32_t vertexCount, double start, double end,
                                std::function<void(double time, std::span<float> positions)> positionsAt);

  // n >= 1 times uniform over [a, b], both ends included (n = 1: a); as anim::Animation::uniformTimes.
  static std::vector<double> uniformTimes(double a, double b, uint32_t n);
  PrimitiveBoxes sample(std::span<const double> times) const;
  FrameSource frames(std::vector<double> times) const;
};

struct SegmentationConfig {
  enum class Mode { Count, Budget };
  Mode mode = Mode::Budget;
  uint32_t count = 1;                 // count mode: K
  MethodSpec method;                  // how each part's tree is built (tsah<k>, sah0, sahstar)
  uint32_t representativeFrames = 5;  // per part, uniform over its build range (ends included)
  uint32_t evaluationFrames = 50;     // uniform over the animation: where costs are measured
  // Each tree is built for its part extended by overlap / 2 on each inner side, so consecutive
  // trees overlap by `overlap` and the runtimes switch at the middle of the overlap.
  double overlap = 0.0;

  // Budget mode.
  double budget = 1.05;               // relative: factor of the reference cost; absolute: the cost
  bool budgetRelative = true;
  // Relative budget: the reference is a per-frame optimized SAH tree (buildOptimizedSah) on this
  // many evaluation frames spread uniformly (0, or at least evaluationFrames: every one), linear
  // in between; or referenceCosts when given (one per evaluation frame, e.g. SAH-rebuild's).
  uint32_t referenceFrames = 10;
  std::vector<double> referenceCosts;
  uint32_t maxTrees = 64;             // the budget search stops adding trees here
  bool refine = true;                 // budget: balance the parts after the greedy pass

  uint32_t maxPasses = 3;             // local search passes over all split points
  BaselineConfig baseline;            // cost, leaf size, optimizer (seed), threads, progress
  // Who builds the candidate and reference trees (see above); null: this process, the candidates
  // one at a time and the reference trees on `baseline.threads` threads.
  WorkDealer* dealer = nullptr;
};

struct SegmentationResult {
  std::vector<TimeRange> parts;        // where each tree is used (switch points = part boundaries)
  std::vector<TimeRange> buildRanges;  // what each tree was built for (parts widened by the overlap)
  std::vector<Bvh> trees;
  // Each tree's method: the configured one (tsah, sah0, sahstar) or, for a budget part of one
  // evaluation interval whose tree missed the bound, "sah-frame": an optimized SAH tree of the
  // part's first frame (one box set).
  std::vector<std::string> methods;
  std::vector<double> buildSeconds;    // wall time of each tree's build
  std::vector<InsertionOptimizer::Result> optimizations;  // T-SAH: the optimizer's report per tree

  std::vector<double> times;           // the evaluation frames
  std::vector<double> costs;           // Eq. 1 at each, with the tree of its part
  std::vector<double> reference;       // relative budget: the reference cost at each (else empty)
  std::vector<double> bound;           // budget: the bound at each (else empty)
  bool budgetMet = true;               // budget: every evaluation frame within its bound
  double average = 0.0, maximum = 0.0; // of costs
  uint32_t treesBuilt = 0;             // candidate trees built by the search (the cache's size)
  double referenceSeconds = 0.0;       // building the reference trees
  double searchSeconds = 0.0;          // everything, the reference included
};

// Runs the configured mode. Throws tsah::ConfigError for a bad configuration (count 0, a rebuild
// method, fewer than 2 evaluation frames, overlap too long), tsah::DataError for a timeline of
// length 0 (not an animation) or without boxes.
SegmentationResult segmentTimeline(const Timeline& timeline, const SegmentationConfig& config);

// The same trees and evaluation for given parts (e.g. equalTimeRanges): no search.
SegmentationResult evaluateParts(const Timeline& timeline, std::span<const TimeRange> parts,
                                 const SegmentationConfig& config);

}  // namespace tsah
