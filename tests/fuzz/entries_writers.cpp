// Fuzz entry for the writers: an animation made from the bytes is written as .tanim (what `tsah
// resample` writes for a scene), PC2, MDD or a two-tree set file, and what a writer accepts its own
// reader must read back unchanged. A writer may refuse (tsah::Error, one line); writing something
// its reader refuses (PC2/MDD times beyond float32 written as infinities) or reads differently is a
// finding.
//
// Input: byte 0 picks the writer (mod 4: tanim, pc2, mdd, treeset), byte 1 the vertex count
// (3 + b % 8, triangles as a strip), byte 2 the keyframes (1 + b % 6); then the keyframe times as
// little-endian doubles and the coordinates as floats. Shorter inputs are ignored.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <vector>

#include "anim/animation.hpp"
#include "anim/point_cache.hpp"
#include "anim/tanim.hpp"
#include "entries.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/io/tree_set.hpp"

namespace tsah::fuzz {

namespace {

enum class Writer { Tanim, Pc2, Mdd, TreeSet };

struct Described {
  Writer writer;
  anim::Animation animation;
};

// The animation the bytes describe, or nothing when they are too short or the animation's own
// checks refuse it (that is the constructor's business, not the writers').
std::optional<Described> describe(std::span<const uint8_t> data) {
  if (data.size() < 3) return std::nullopt;
  const auto writer = Writer(data[0] % 4);
  const uint32_t vertices = 3 + data[1] % 8, frames = 1 + data[2] % 6;
  const std::size_t need = 3 + frames * sizeof(double) + std::size_t(frames) * vertices * 3 * sizeof(float);
  if (data.size() < need) return std::nullopt;
  std::vector<double> times(frames);
  std::memcpy(times.data(), data.data() + 3, frames * sizeof(double));
  std::vector<float> positions(std::size_t(frames) * vertices * 3);
  std::memcpy(positions.data(), data.data() + 3 + frames * sizeof(double), positions.size() * sizeof(float));
  std::vector<uint32_t> indices;
  for (uint32_t v = 0; v + 2 < vertices; ++v) indices.insert(indices.end(), {v, v + 1, v + 2});
  try {
    return Described{writer, anim::Animation(std::move(indices), vertices, std::move(positions), std::move(times),
                                             "fuzz")};
  } catch (const tsah::Error& e) {
    requireOneLine(e.what());
    return std::nullopt;
  }
}

// Runs a writer; a clean refusal ends the case (nullopt).
template <typename F>
std::optional<std::vector<uint8_t>> written(F&& write) {
  try {
    return write();
  } catch (const tsah::Error& e) {
    requireOneLine(e.what());
    return std::nullopt;
  }
}

void fail(const char* what) { throw std::logic_error(std::string("writers: ") + what); }

void requireSamePositions(const anim::Animation& a, std::span<const float> back, const char* format) {
  const std::vector<float> expected = a.allPositions();
  if (!std::equal(back.begin(), back.end(), expected.begin(), expected.end()))
    fail((std::string(format) + " positions change in a round trip").c_str());
}

void pointCacheRoundTrip(const anim::Animation& a, anim::PointCacheFormat format) {
  const bool pc2 = format == anim::PointCacheFormat::Pc2;
  const auto bytes = written([&] { return pc2 ? anim::encodePc2(a) : anim::encodeMdd(a); });
  if (!bytes) return;
  anim::PointCache back;
  try {
    back = anim::decodePointCache(*bytes, "fuzz", format);
  } catch (const tsah::Error& e) {
    fail((std::string(pc2 ? "PC2" : "MDD") + " written, then refused by its reader: " + e.what()).c_str());
  }
  requireSamePositions(a, back.positions, pc2 ? "PC2" : "MDD");
  if (back.times.size() != a.keyframeCount()) fail("point cache keyframe count changes in a round trip");
  // MDD keeps float times: each within float precision of its own. PC2 keeps a float start and
  // rate, and its writer puts times within 1e-4 of a step (or of the time) of that grid on it; the
  // grid itself is only as fine as the float precision of the range (a start of -3.7e9 moves a
  // time of 0.48 by hundreds).
  const std::size_t n = a.keyframeCount();
  const double step = n > 1 ? (a.endTime() - a.startTime()) / double(n - 1) : 1.0;
  const double range = std::max({1.0, std::fabs(a.startTime()), std::fabs(a.endTime())});
  for (std::size_t i = 0; i < back.times.size(); ++i) {
    const double t = a.times()[i];
    const double tolerance = pc2 ? 1.01e-4 * std::max(std::fabs(step), std::fabs(t)) + 1e-6 * range
                                 : 1e-6 * std::max(1.0, std::fabs(t));
    if (!(std::fabs(back.times[i] - t) <= tolerance)) fail("point cache times change in a round trip");
  }
}

void tanimRoundTrip(const anim::Animation& a) {
  const auto bytes = written([&] { return anim::encodeTanim(a); });
  if (!bytes) return;
  anim::Animation back;
  try {
    back = anim::decodeTanim(*bytes, "fuzz.tanim");
  } catch (const tsah::Error& e) {
    fail((std::string(".tanim written, then refused by its reader: ") + e.what()).c_str());
  }
  if (!std::equal(back.indices().begin(), back.indices().end(), a.indices().begin(), a.indices().end()) ||
      !std::equal(back.times().begin(), back.times().end(), a.times().begin(), a.times().end()))
    fail(".tanim topology or times change in a round trip");
  requireSamePositions(a, back.allPositions(), ".tanim");
}

// Two trees (one when there is one keyframe) over the keyframes, each part its own range.
void treeSetRoundTrip(const anim::Animation& a) {
  const uint32_t parts = a.keyframeCount() >= 2 ? 2 : 1;
  std::vector<Bvh> trees;
  std::vector<BvhBuildInfo> builds;
  std::vector<TimeRange> ranges;
  const PrimitiveBoxes boxes = triangleBoxes(a.indices(), a.allPositions(), a.keyframeCount());
  for (uint32_t p = 0; p < parts; ++p) {
    Bvh tree = SweepSahBuilder().build(boxes.frame(p));
    refit(tree, boxes);
    trees.push_back(std::move(tree));
    const double start = p == 0 ? a.startTime() : a.times()[1], end = p + 1 == parts ? a.endTime() : a.times()[1];
    ranges.push_back({start, end});
    BvhBuildInfo info;
    info.vertexCount = a.vertexCount();
    info.topologyHash = topologyHash(a.indices());
    builds.push_back(info);
  }
  const auto bytes = written([&] { return encodeTreeSetFile(trees, builds, ranges, TreeSetInfo{}); });
  if (!bytes) return;
  TreeSet back;
  try {
    back = decodeTreeSetFile(*bytes, "fuzz.tbvh");
  } catch (const tsah::Error& e) {
    fail((std::string("tree set written, then refused by its reader: ") + e.what()).c_str());
  }
  if (back.ranges != ranges || back.size() != parts) fail("tree-set ranges change in a round trip");
}

}  // namespace

void writers(std::span<const uint8_t> data) {
  const std::optional<Described> d = describe(data);
  if (!d) return;
  switch (d->writer) {
    case Writer::Tanim: return tanimRoundTrip(d->animation);
    case Writer::Pc2: return pointCacheRoundTrip(d->animation, anim::PointCacheFormat::Pc2);
    case Writer::Mdd: return pointCacheRoundTrip(d->animation, anim::PointCacheFormat::Mdd);
    case Writer::TreeSet: return treeSetRoundTrip(d->animation);
  }
}

}  // namespace tsah::fuzz
