#pragma once
// Segmenting an animation (the paper's BART Museum* experiment): K trees, each optimized for one of
// K consecutive equal-time parts of the animation; a frame is traced with the tree of its part.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "tsah/baselines.hpp"

namespace tsah::bench {

struct TimeSegment {
  double start = 0.0, end = 0.0;
};

// count consecutive parts of [start, end] of equal length (the last ends exactly at end). Throws
// std::invalid_argument when count is 0 or end < start.
std::vector<TimeSegment> equalTimeSegments(double start, double end, uint32_t count);

// The part that time t belongs to: the last one that starts at or before t (a time on a boundary
// belongs to the later part); times outside [first start, last end] go to the first / last part.
uint32_t segmentOf(std::span<const TimeSegment> segments, double t);

// The file of part `index` of a multi-tree output: OUT.tbvh -> OUT_seg<index>.tbvh (the suffix goes
// before the extension; a name without extension gets it appended).
std::string segmentPath(const std::string& output, uint32_t index);

struct SegmentTree {
  TimeSegment segment;
  Bvh bvh;                                  // boxes of the part's representative frames
  uint32_t representativeFrames = 0;
  double buildSeconds = 0.0;                // wall time of this part's build
  InsertionOptimizer::Result optimization;  // T-SAH: the optimizer's report (bvh member empty)
};

// One tree per part: method (any single-tree method) built over `frames` representative frames
// uniform in time within the part (both ends included). Throws std::invalid_argument for a method
// that is not a single tree (rebuild) and when the animation has fewer than two keyframes.
std::vector<SegmentTree> buildSegmentTrees(const anim::Animation& animation, uint32_t segmentCount, uint32_t frames,
                                           const MethodSpec& method, const BaselineConfig& config);

// Eq. 1 at each of `times`, every frame evaluated with the tree of its part (refitted to it).
std::vector<double> evaluateSegmentTrees(const anim::Animation& animation, std::span<const SegmentTree> trees,
                                         std::span<const double> times, const CostModel& cost, unsigned threads = 0);

}  // namespace tsah::bench
