#include "bench/segments.hpp"

#include "animation_frames.hpp"

#include <chrono>
#include <filesystem>
#include <stdexcept>

namespace tsah::bench {

std::vector<TimeSegment> equalTimeSegments(double start, double end, uint32_t count) {
  if (count == 0) throw std::invalid_argument("the number of segments must be at least 1");
  if (!(end >= start)) throw std::invalid_argument("segments: the time range ends before it starts");
  std::vector<TimeSegment> segments(count);
  const double length = (end - start) / double(count);
  for (uint32_t i = 0; i < count; ++i) {
    segments[i].start = i == 0 ? start : segments[i - 1].end;
    segments[i].end = i + 1 == count ? end : start + length * double(i + 1);
  }
  return segments;
}

uint32_t segmentOf(std::span<const TimeSegment> segments, double t) {
  uint32_t index = 0;
  for (uint32_t i = 1; i < segments.size(); ++i)
    if (t >= segments[i].start) index = i;
  return index;
}

std::string segmentPath(const std::string& output, uint32_t index) {
  const std::filesystem::path p(output);
  const std::string suffix = "_seg" + std::to_string(index);
  if (!p.has_extension() || p.stem().empty()) return output + suffix;
  return (p.parent_path() / (p.stem().string() + suffix + p.extension().string())).string();
}

std::vector<SegmentTree> buildSegmentTrees(const anim::Animation& animation, uint32_t segmentCount, uint32_t frames,
                                           const MethodSpec& method, const BaselineConfig& config) {
  if (method.method == Method::SahRebuild)
    throw std::invalid_argument("segments: SAH-rebuild builds a tree per frame, not one per segment");
  if (animation.keyframeCount() < 2) throw std::invalid_argument("segments need an animation (at least two keyframes)");
  std::vector<SegmentTree> trees;
  for (const TimeSegment& s : equalTimeSegments(animation.startTime(), animation.endTime(), segmentCount)) {
    const auto start = std::chrono::steady_clock::now();
    const anim::Animation part = animation.segment(s.start, s.end);
    const anim::Animation rep = part.resample(frames);
    const PrimitiveBoxes boxes = triangleBoxes(rep.indices(), rep.allPositions(), frames);
    SegmentTree tree;
    tree.segment = s;
    tree.representativeFrames = frames;
    tree.bvh = buildMethod(method, boxes, config, &tree.optimization);
    tree.buildSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    trees.push_back(std::move(tree));
  }
  return trees;
}

std::vector<double> evaluateSegmentTrees(const anim::Animation& animation, std::span<const SegmentTree> trees,
                                         std::span<const double> times, const CostModel& cost, unsigned threads) {
  std::vector<TimeSegment> segments;
  for (const SegmentTree& t : trees) segments.push_back(t.segment);
  std::vector<double> costs(times.size(), 0.0);
  for (uint32_t s = 0; s < trees.size(); ++s) {
    std::vector<double> mine;  // the times of this part, in order
    std::vector<std::size_t> where;
    for (std::size_t i = 0; i < times.size(); ++i)
      if (segmentOf(segments, times[i]) == s) {
        mine.push_back(times[i]);
        where.push_back(i);
      }
    if (mine.empty()) continue;
    const std::vector<double> c = evaluateFrames(trees[s].bvh, tsah::cli::animationFrames(animation, mine), cost, threads);
    for (std::size_t j = 0; j < c.size(); ++j) costs[where[j]] = c[j];
  }
  return costs;
}

}  // namespace tsah::bench
