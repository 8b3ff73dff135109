#include "tsah/io/tree_set.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>

#include "tsah/base/assert.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/files.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "io/tbvh_io.hpp"

namespace tsah {

namespace {

constexpr uint32_t kFlagBudgetRelative = 1;
constexpr std::size_t kReservedWords = 2;  // header padding up to kTbvhSetHeaderBytes, written as 0
// The smallest valid version 1 file: header, no interior node, one root box, one slot, checksum.
constexpr uint64_t kMinTreeBytes = kTbvhHeaderBytes + sizeof(Aabb) + 4 + 4;

using detail::align16;

std::string describeRange(const TimeRange& r) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "[%.9g, %.9g]", r.start, r.end);
  return buf;
}

}  // namespace

std::vector<TimeRange> equalTimeRanges(double start, double end, uint32_t count) {
  if (count == 0) throw tsah::ConfigError("the number of parts must be at least 1");
  if (!(end >= start)) throw tsah::ConfigError("parts: the time range ends before it starts");
  std::vector<TimeRange> parts(count);
  const double length = (end - start) / double(count);
  for (uint32_t i = 0; i < count; ++i) {
    parts[i].start = i == 0 ? start : parts[i - 1].end;
    parts[i].end = i + 1 == count ? end : start + length * double(i + 1);
  }
  return parts;
}

double switchTime(std::span<const TimeRange> ranges, uint32_t s) {
  return 0.5 * (ranges[s].end + ranges[s + 1].start);
}

uint32_t treeIndexAt(std::span<const TimeRange> ranges, double t) {
  uint32_t index = 0;
  while (index + 1 < ranges.size() && t >= switchTime(ranges, index)) ++index;
  return index;
}

std::optional<std::string> validateTimeRanges(std::span<const TimeRange> ranges) {
  if (ranges.empty()) return "a tree set needs at least one time range";
  for (std::size_t s = 0; s < ranges.size(); ++s) {
    const TimeRange& r = ranges[s];
    if (!std::isfinite(r.start) || !std::isfinite(r.end) || r.end < r.start)
      return "time range " + std::to_string(s) + " " + describeRange(r) + " is not finite and ordered";
    if (s == 0) continue;
    const TimeRange& p = ranges[s - 1];
    if (!(r.start > p.start) || !(r.end > p.end))
      return "time ranges " + std::to_string(s - 1) + " and " + std::to_string(s) + " are not sorted";
    if (r.start > p.end)
      return "time ranges " + std::to_string(s - 1) + " and " + std::to_string(s) + " leave a gap " +
             describeRange({p.end, r.start});
  }
  return std::nullopt;
}

namespace {

// encodeTreeSetFile's file as its parts (TreeImagesFileParts) over `flats`, which it fills with the
// trees flattened (the images point into them: the caller keeps them while it writes the parts).
TreeImagesFileParts treeSetParts(std::span<const Bvh> trees, std::span<const BvhBuildInfo> builds,
                                 std::span<const TimeRange> ranges, const TreeSetInfo& info,
                                 std::vector<FlatBvh>& flats) {
  if (trees.size() != builds.size() || trees.size() != ranges.size())
    throw tsah::DataError(".tbvh set: " + std::to_string(trees.size()) + " trees, " + std::to_string(builds.size()) +
                          " build records and " + std::to_string(ranges.size()) + " time ranges");
  if (trees.size() > kTbvhMaxTrees)
    throw tsah::DataError(".tbvh set: more than " + std::to_string(kTbvhMaxTrees) + " trees");
  if (auto problem = validateTimeRanges(ranges)) throw tsah::DataError(".tbvh set: " + *problem);
  if (!std::isfinite(info.overlap) || info.overlap < 0 || !std::isfinite(info.budget) || info.budget < 0)
    throw tsah::ConfigError(".tbvh set: overlap and budget must be finite and >= 0");

  const uint32_t triangleCount = trees[0].primCount();
  for (std::size_t s = 0; s < trees.size(); ++s)
    if (trees[s].primCount() != triangleCount || builds[s].vertexCount != builds[0].vertexCount ||
        builds[s].topologyHash != builds[0].topologyHash)
      throw tsah::DataError(".tbvh set: tree " + std::to_string(s) +
                            " was built for a different animation than tree 0");
  TreeImagesFileParts out;
  flats.assign(trees.size(), FlatBvh{});
  out.images.resize(trees.size());
  for (std::size_t s = 0; s < trees.size(); ++s) {  // in order: the first tree that cannot be encoded throws
    BvhBuildInfo b = builds[s];
    b.timeStart = ranges[s].start;
    b.timeEnd = ranges[s].end;
    flats[s] = flattenBvh(trees[s]);
    out.images[s] = bvhFileParts(flats[s], b);
  }

  tsah::ByteWriter w;
  w.write(detail::kTbvhMagic);
  w.write(kTbvhSetVersion);
  w.write(kTbvhSetHeaderBytes);
  w.write(kTbvhSetEntryBytes);
  w.write(static_cast<uint32_t>(trees.size()));
  w.write(triangleCount);
  w.write(builds[0].vertexCount);
  w.write(builds[0].topologyHash);
  w.write(info.budgetRelative ? kFlagBudgetRelative : 0u);
  w.write(ranges.front().start);
  w.write(ranges.back().end);
  w.write(info.overlap);
  w.write(info.budget);
  detail::writeTbvhName(w, info.segmentation, "segmentation");
  for (std::size_t i = 0; i < kReservedWords; ++i) w.write(uint32_t{0});
  TSAH_ASSERT(w.buffer().size() == kTbvhSetHeaderBytes, ".tbvh set header size mismatch");
  uint64_t offset = align16(kTbvhSetHeaderBytes + uint64_t(kTbvhSetEntryBytes) * trees.size());
  for (std::size_t s = 0; s < trees.size(); ++s) {
    w.write(ranges[s].start);
    w.write(ranges[s].end);
    w.write(offset);
    w.write(out.images[s].size());
    offset = align16(offset + out.images[s].size());
  }
  out.tables = std::move(w.buffer());
  out.seal();
  return out;
}

}  // namespace

std::vector<uint8_t> encodeTreeSetFile(std::span<const Bvh> trees, std::span<const BvhBuildInfo> builds,
                                       std::span<const TimeRange> ranges, const TreeSetInfo& info) {
  std::vector<FlatBvh> flats;
  return treeSetParts(trees, builds, ranges, info, flats).bytes();
}

namespace {

TreeSet decodeVersion1(std::span<const uint8_t> bytes, const std::string& file) {
  TreeSet set;
  set.version = kTbvhVersion;
  BvhBuildInfo build;
  set.trees.push_back(decodeFlatBvhFile(bytes, file, &build));
  set.ranges.push_back({build.timeStart, build.timeEnd});
  set.builds.push_back(std::move(build));
  return set;
}

}  // namespace

TreeSet decodeTreeSetFile(std::span<const uint8_t> bytes, const std::string& file) {
  tsah::ByteReader r(bytes, file);
  if (r.read<std::array<char, 8>>("magic") != detail::kTbvhMagic) r.fail("not a .tbvh file (bad magic)");
  const auto version = r.read<uint32_t>("version");
  if (version == kTbvhVersion) return decodeVersion1(bytes, file);
  if (version == 3)
    r.fail("holds a two-level scene (.tbvh version 3): read it with its scene (tsah::loadTwoLevelSceneFile)");
  if (version != kTbvhSetVersion)
    r.fail("unsupported .tbvh version " + std::to_string(version) + " (this reader knows 1 and 2)");
  if (r.read<uint32_t>("header size") != kTbvhSetHeaderBytes)
    r.fail("tree set header size is not " + std::to_string(kTbvhSetHeaderBytes));
  if (r.read<uint32_t>("entry size") != kTbvhSetEntryBytes)
    r.fail("tree set entry size is not " + std::to_string(kTbvhSetEntryBytes));
  const auto treeCount = r.read<uint32_t>("tree count");
  const auto triangleCount = r.read<uint32_t>("triangle count");
  const auto vertexCount = r.read<uint32_t>("vertex count");
  const auto hash = r.read<uint32_t>("topology hash");
  const auto flags = r.read<uint32_t>("flags");
  const auto timeStart = r.read<double>("time start");
  const auto timeEnd = r.read<double>("time end");
  TreeSet set;
  set.version = kTbvhSetVersion;
  set.info.overlap = r.read<double>("overlap");
  set.info.budget = r.read<double>("budget");
  set.info.segmentation = detail::readTbvhName(r, "segmentation");
  set.info.budgetRelative = (flags & kFlagBudgetRelative) != 0;
  for (std::size_t i = 0; i < kReservedWords; ++i)
    if (r.read<uint32_t>("reserved") != 0) r.fail("reserved header words must be 0");
  if ((flags & ~kFlagBudgetRelative) != 0) r.fail("unknown flags " + std::to_string(flags));

  // Counts against the byte count before any allocation.
  if (treeCount == 0 || treeCount > kTbvhMaxTrees)
    r.fail("tree count " + std::to_string(treeCount) + " is not in 1.." + std::to_string(kTbvhMaxTrees));
  const uint64_t tableEnd = kTbvhSetHeaderBytes + uint64_t(kTbvhSetEntryBytes) * treeCount;
  if (bytes.size() < tableEnd + uint64_t(treeCount) * kMinTreeBytes + 4)
    r.fail("file size " + std::to_string(bytes.size()) + " is too small for " + std::to_string(treeCount) + " trees");
  const std::size_t crcOffset = bytes.size() - 4;
  uint32_t storedCrc;
  std::memcpy(&storedCrc, bytes.data() + crcOffset, 4);
  if (tsah::crc32(bytes.data(), crcOffset) != storedCrc) r.fail("checksum mismatch (the file is corrupt)");
  if (!std::isfinite(set.info.overlap) || set.info.overlap < 0 || !std::isfinite(set.info.budget) ||
      set.info.budget < 0)
    r.fail("overlap and budget must be finite and >= 0");

  struct Entry {
    uint64_t offset, size;
  };
  std::vector<Entry> entries(treeCount);
  set.ranges.resize(treeCount);
  uint64_t expected = align16(tableEnd);
  for (uint32_t s = 0; s < treeCount; ++s) {
    set.ranges[s].start = r.read<double>("range start");
    set.ranges[s].end = r.read<double>("range end");
    entries[s].offset = r.read<uint64_t>("tree offset");
    entries[s].size = r.read<uint64_t>("tree size");
    const std::string which = "tree " + std::to_string(s);
    if (entries[s].offset != expected)
      r.fail(which + " starts at byte " + std::to_string(entries[s].offset) + ", expected " + std::to_string(expected));
    if (entries[s].size < kMinTreeBytes || entries[s].size > crcOffset - std::min<uint64_t>(expected, crcOffset))
      r.fail(which + " size " + std::to_string(entries[s].size) + " does not fit the file");
    expected = align16(entries[s].offset + entries[s].size);
  }
  if (entries.back().offset + entries.back().size != crcOffset)
    r.fail("the last tree does not end where the checksum starts");
  for (uint32_t s = 0; s + 1 < treeCount; ++s)
    for (uint64_t b = entries[s].offset + entries[s].size; b < entries[s + 1].offset; ++b)
      if (bytes[b] != 0) r.fail("padding after tree " + std::to_string(s) + " must be 0");
  for (uint64_t b = tableEnd; b < entries[0].offset; ++b)
    if (bytes[b] != 0) r.fail("padding before tree 0 must be 0");
  if (auto problem = validateTimeRanges(set.ranges)) r.fail(*problem);
  if (set.ranges.front().start != timeStart || set.ranges.back().end != timeEnd)
    r.fail("the time ranges do not cover the set's range " + describeRange({timeStart, timeEnd}));

  for (uint32_t s = 0; s < treeCount; ++s) {
    const std::string which = "tree " + std::to_string(s);
    const auto image = bytes.subspan(entries[s].offset, entries[s].size);
    if (image.size() >= 12) {
      uint32_t innerVersion;
      std::memcpy(&innerVersion, image.data() + 8, 4);
      if (innerVersion != kTbvhVersion) r.fail(which + " is not a version 1 tree");
    }
    BvhBuildInfo build;
    set.trees.push_back(decodeFlatBvhFile(image, file + " (" + which + ")", &build));
    if (build.triangleCount != triangleCount || build.vertexCount != vertexCount || build.topologyHash != hash)
      r.fail(which + " was built for a different animation than the set (triangles, vertices or topology hash)");
    if (build.timeStart != set.ranges[s].start || build.timeEnd != set.ranges[s].end)
      r.fail(which + "'s time range differs from the set's table");
    set.builds.push_back(std::move(build));
  }
  return set;
}

void saveTreeSetFile(const std::string& path, std::span<const Bvh> trees, std::span<const BvhBuildInfo> builds,
                     std::span<const TimeRange> ranges, const TreeSetInfo& info) {
  std::vector<FlatBvh> flats;
  const TreeImagesFileParts file = treeSetParts(trees, builds, ranges, info, flats);
  tsah::writeFileAtomically(path, file.parts());
}

TreeSet loadTreeSetFile(const std::string& path) { return decodeTreeSetFile(tsah::readFile(path), path); }

}  // namespace tsah
