#pragma once
// A tree set: K trees over one animation, each built for one part of its time range, and the rule
// that picks the tree of a frame. Stored as a .tbvh file of version 2 (docs/tbvh-format.md); a
// version 1 file reads as a set of one tree.
//
// Switching rule (the CPU and GPU runtimes and the bench all call treeIndexAt): parts are sorted;
// consecutive parts touch (end of s == start of s+1) or overlap (end of s > start of s+1). The
// switch from tree s to tree s+1 happens at the middle of their overlap (at the shared boundary
// when they only touch); a time exactly on a switch point belongs to the later tree, and times
// outside the set's range go to the first or last tree.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah {

inline constexpr uint32_t kTbvhSetVersion = 2;
inline constexpr uint32_t kTbvhSetHeaderBytes = 96;
inline constexpr uint32_t kTbvhSetEntryBytes = 32;
inline constexpr uint32_t kTbvhMaxTrees = 4096;

struct TimeRange {
  double start = 0.0, end = 0.0;
  bool operator==(const TimeRange&) const = default;
};

// count consecutive parts of [start, end] of equal length (the last ends exactly at end). Throws
// tsah::ConfigError when count is 0 or end < start.
std::vector<TimeRange> equalTimeRanges(double start, double end, uint32_t count);

// The time where tree s hands over to tree s+1: the middle of ranges[s].end and ranges[s+1].start.
double switchTime(std::span<const TimeRange> ranges, uint32_t s);
// The tree of time t (see the rule above). ranges must be non-empty.
uint32_t treeIndexAt(std::span<const TimeRange> ranges, double t);

// Checks the rules of a set's ranges: non-empty, finite, start <= end, starts and ends strictly
// increasing, consecutive parts touching or overlapping (no gap). Then the switch times increase
// strictly and each tree is used only inside its own range. Returns the first violation.
std::optional<std::string> validateTimeRanges(std::span<const TimeRange> ranges);

// How a set was segmented (stored in the version 2 header, printed by `tsah info`).
struct TreeSetInfo {
  std::string segmentation = "single";  // single, equal, count, count-peak, budget (<= 15 ASCII chars)
  double overlap = 0.0;                  // the overlap asked for (seconds); informative
  double budget = 0.0;                   // the cost bound of a budget segmentation (0: none)
  bool budgetRelative = false;           // budget is a factor of the per-frame optimized cost
};

struct TreeSet {
  TreeSetInfo info;
  uint32_t version = kTbvhSetVersion;   // of the file it was read from (1 or 2)
  std::vector<TimeRange> ranges;        // one per tree, sorted
  std::vector<FlatBvh> trees;           // canonical flat trees with their stored box sets
  std::vector<BvhBuildInfo> builds;     // one per tree (its time range equals ranges[s])

  uint32_t size() const { return static_cast<uint32_t>(trees.size()); }
  uint32_t treeAt(double t) const { return treeIndexAt(ranges, t); }
};

// Writes K >= 1 trees as a version 2 file. builds[s].timeStart/timeEnd are set to ranges[s];
// every tree must hold the same triangles (count, vertex count, topology hash). Throws
// tsah::DataError when the ranges break the rules above, the counts differ, or a tree cannot be
// encoded, tsah::ConfigError for a negative or non-finite overlap or budget or a name that does not fit.
std::vector<uint8_t> encodeTreeSetFile(std::span<const Bvh> trees, std::span<const BvhBuildInfo> builds,
                                       std::span<const TimeRange> ranges, const TreeSetInfo& info);
// Reads a version 1 (one tree; its time range is the part) or version 2 file, validating
// everything before use (docs/tbvh-format.md); throws tsah::FileError naming `file`.
TreeSet decodeTreeSetFile(std::span<const uint8_t> bytes, const std::string& file);

void saveTreeSetFile(const std::string& path, std::span<const Bvh> trees, std::span<const BvhBuildInfo> builds,
                     std::span<const TimeRange> ranges, const TreeSetInfo& info);  // atomic
TreeSet loadTreeSetFile(const std::string& path);

}  // namespace tsah
