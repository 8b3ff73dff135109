#include "tsah/io/two_level_file.hpp"

#include <array>
#include <cmath>
#include <cstring>

#include "tsah/base/assert.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/parallel_each.hpp"
#include "io/tbvh_io.hpp"

namespace tsah {

namespace {

using detail::align16;

constexpr uint32_t kInstanceEntryBytes = 8;   // u32 blas, u32 pose
constexpr uint32_t kPoseEntryBytes = 24;      // u32 blas, u32 outside, f64 offset, f64 speed
constexpr uint32_t kTreeEntryBytes = 16;      // u64 offset, u64 size
constexpr uint32_t kFlattenedEntryBytes = 4;  // u32 object id
// The smallest valid version 1 file: header, no interior node, one root box, one slot, checksum.
constexpr uint64_t kMinTreeBytes = kTbvhHeaderBytes + sizeof(Aabb) + 4 + 4;

uint64_t tablesEnd(uint64_t trees, uint64_t instances, uint64_t poses, uint64_t flattened) {
  return kTbvhTwoLevelHeaderBytes + kInstanceEntryBytes * instances + kPoseEntryBytes * poses +
         kFlattenedEntryBytes * flattened + kTreeEntryBytes * trees;
}

// Flattened object ids: strictly increasing (no duplicates).
std::optional<std::string> validateFlattenedObjects(std::span<const uint32_t> objects) {
  for (std::size_t k = 1; k < objects.size(); ++k)
    if (objects[k] <= objects[k - 1])
      return "flattened object " + std::to_string(objects[k]) + " follows " + std::to_string(objects[k - 1]) +
             " (the ids must be increasing, without duplicates)";
  return std::nullopt;
}

// The encoders' checks of their arguments, before any tree is flattened or encoded.
void requireEncodable(std::size_t blasCount, std::size_t buildCount, std::span<const uint32_t> tlasInstances,
                      std::span<const BvhBuildInfo> tlasBuilds, std::span<const uint32_t> instanceBlas,
                      std::span<const uint32_t> instancePose, std::span<const TwoLevelPoseRecord> poses,
                      std::span<const uint32_t> flattenedObjects) {
  if (blasCount != buildCount || blasCount > kTbvhTwoLevelMaxBlas)
    throw DataError(".tbvh two-level: " + std::to_string(blasCount) + " BLAS and " + std::to_string(buildCount) +
                    " build records");
  if (tlasInstances.size() != tlasBuilds.size())
    throw DataError(".tbvh two-level: " + std::to_string(tlasInstances.size()) + " TLAS and " +
                    std::to_string(tlasBuilds.size()) + " TLAS build records");
  // The header's range is the trees' together: checked against itself, the rules of their parts.
  const double start = tlasBuilds.empty() ? 0.0 : tlasBuilds.front().timeStart;
  const double end = tlasBuilds.empty() ? 0.0 : tlasBuilds.back().timeEnd;
  if (auto problem = validateTlasRanges(tlasBuilds, start, end)) throw DataError(".tbvh two-level: " + *problem);
  if (auto problem = validateTwoLevelTables(uint32_t(blasCount), instanceBlas, instancePose, poses))
    throw DataError(".tbvh two-level: " + *problem);
  if (auto problem = validateFlattenedObjects(flattenedObjects)) throw DataError(".tbvh two-level: " + *problem);
  if (flattenedObjects.size() > kTbvhTwoLevelMaxFlattened)
    throw DataError(".tbvh two-level: " + std::to_string(flattenedObjects.size()) + " flattened objects");
  for (std::size_t t = 0; t < tlasInstances.size(); ++t)
    if (tlasInstances[t] != instanceBlas.size())
      throw DataError(".tbvh two-level: TLAS " + std::to_string(t) + " holds " + std::to_string(tlasInstances[t]) +
                      " instances, the table " + std::to_string(instanceBlas.size()));
}

// twoLevelFileParts' work once its arguments passed requireEncodable.
TwoLevelFileParts encodedParts(std::span<const FlatBvh* const> blases, std::span<const BvhBuildInfo> blasBuilds,
                               std::span<const FlatBvh* const> tlases, std::span<const BvhBuildInfo> tlasBuilds,
                               std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                               std::span<const TwoLevelPoseRecord> poses, std::span<const uint32_t> flattenedObjects) {
  TwoLevelFileParts out;
  // Each image with its own checksums, concurrently (the largest trees take the longest).
  const std::size_t trees = blases.size() + tlases.size();
  out.images.resize(trees);
  forEachConcurrently(trees, [&](std::size_t b) {
    const std::size_t t = b - blases.size();
    out.images[b] = b < blases.size() ? bvhFileParts(*blases[b], blasBuilds[b]) : bvhFileParts(*tlases[t], tlasBuilds[t]);
  });

  ByteWriter w;
  w.buffer().reserve(align16(tablesEnd(trees, instanceBlas.size(), poses.size(), flattenedObjects.size())));
  w.write(detail::kTbvhMagic);
  w.write(kTbvhTwoLevelVersion);
  w.write(kTbvhTwoLevelHeaderBytes);
  w.write(uint32_t(blases.size()));
  w.write(uint32_t(instanceBlas.size()));
  w.write(uint32_t(poses.size()));
  w.write(uint32_t(flattenedObjects.size()));
  w.write(tlasBuilds.front().timeStart);
  w.write(tlasBuilds.back().timeEnd);
  // The TLAS count; 0 for one, so that files of one TLAS keep their bytes.
  w.write(tlases.size() == 1 ? uint32_t{0} : uint32_t(tlases.size()));
  for (int i = 0; i < 3; ++i) w.write(uint32_t{0});
  TSAH_ASSERT(w.buffer().size() == kTbvhTwoLevelHeaderBytes, ".tbvh two-level header size mismatch");
  for (std::size_t i = 0; i < instanceBlas.size(); ++i) {
    w.write(instanceBlas[i]);
    w.write(instancePose[i]);
  }
  for (const TwoLevelPoseRecord& p : poses) {
    w.write(p.blas);
    w.write(p.outside);
    w.write(p.offset);
    w.write(p.speed);
  }
  for (uint32_t o : flattenedObjects) w.write(o);
  uint64_t offset = align16(tablesEnd(trees, instanceBlas.size(), poses.size(), flattenedObjects.size()));
  for (const BvhFileParts& image : out.images) {
    w.write(offset);
    w.write(image.size());
    offset = align16(offset + image.size());
  }
  out.tables = std::move(w.buffer());
  out.seal();
  return out;
}

}  // namespace

std::optional<std::string> validateTwoLevelTables(uint32_t blasCount, std::span<const uint32_t> instanceBlas,
                                                  std::span<const uint32_t> instancePose,
                                                  std::span<const TwoLevelPoseRecord> poses) {
  if (blasCount == 0) return "a two-level scene needs at least one BLAS";
  if (instanceBlas.empty()) return "a two-level scene needs at least one instance";
  if (instancePose.size() != instanceBlas.size()) return "the instance table's columns differ in length";
  for (std::size_t p = 0; p < poses.size(); ++p) {
    const TwoLevelPoseRecord& pose = poses[p];
    if (pose.blas >= blasCount) return "pose " + std::to_string(p) + " names BLAS " + std::to_string(pose.blas) + " of " + std::to_string(blasCount);
    if (pose.outside > 1) return "pose " + std::to_string(p) + " has an unknown outside mode " + std::to_string(pose.outside);
    if (!std::isfinite(pose.offset) || !std::isfinite(pose.speed) || pose.speed < 0.0)
      return "pose " + std::to_string(p) + " has a non-finite offset or a speed that is not finite and >= 0";
  }
  // Per BLAS: -1 unknown, 0 static (no pose), 1 animated (posed).
  std::vector<int> posed(blasCount, -1);
  std::vector<uint8_t> used(poses.size(), 0);
  for (std::size_t i = 0; i < instanceBlas.size(); ++i) {
    const std::string which = "instance " + std::to_string(i);
    const uint32_t blas = instanceBlas[i], pose = instancePose[i];
    if (blas >= blasCount) return which + " names BLAS " + std::to_string(blas) + " of " + std::to_string(blasCount);
    if (pose != kTbvhNoPose && pose >= poses.size()) return which + " names pose " + std::to_string(pose) + " of " + std::to_string(poses.size());
    if (pose != kTbvhNoPose && poses[pose].blas != blas) return which + "'s pose belongs to another BLAS";
    const int kind = pose == kTbvhNoPose ? 0 : 1;
    if (posed[blas] != -1 && posed[blas] != kind) return "the instances of BLAS " + std::to_string(blas) + " are posed and unposed";
    posed[blas] = kind;
    if (pose != kTbvhNoPose) used[pose] = 1;
  }
  for (std::size_t p = 0; p < poses.size(); ++p)
    if (!used[p]) return "pose " + std::to_string(p) + " is shown by no instance";
  return std::nullopt;
}

std::optional<std::string> validateTlasRanges(std::span<const BvhBuildInfo> tlasBuilds, double start, double end) {
  if (tlasBuilds.empty() || tlasBuilds.size() > kTbvhTwoLevelMaxTlas)
    return "TLAS count " + std::to_string(tlasBuilds.size()) + " is not in 1.." + std::to_string(kTbvhTwoLevelMaxTlas);
  const bool single = tlasBuilds.size() == 1;
  for (std::size_t t = 0; t < tlasBuilds.size(); ++t) {
    const BvhBuildInfo& b = tlasBuilds[t];
    const std::string which = "TLAS " + std::to_string(t);
    if (!std::isfinite(b.timeStart) || !std::isfinite(b.timeEnd) || b.timeEnd < b.timeStart ||
        (!single && b.timeEnd == b.timeStart))
      return which + "'s time range is not finite and ordered" + (single ? "" : " with start < end");
    if (t == 0 && b.timeStart != start) return "TLAS 0 does not start where the header's time range does";
    if (t > 0 && b.timeStart != tlasBuilds[t - 1].timeEnd) return which + " does not start where TLAS " + std::to_string(t - 1) + " ends";
  }
  if (tlasBuilds.back().timeEnd != end) return "the last TLAS does not end where the header's time range does";
  return std::nullopt;
}

std::vector<uint8_t> encodeTwoLevelFile(std::span<const Bvh> blases, std::span<const BvhBuildInfo> blasBuilds,
                                        std::span<const Bvh> tlases, std::span<const BvhBuildInfo> tlasBuilds,
                                        std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                        std::span<const TwoLevelPoseRecord> poses,
                                        std::span<const uint32_t> flattenedObjects) {
  std::vector<const Bvh*> trees;
  for (const Bvh& b : blases) trees.push_back(&b);
  return encodeTwoLevelFile(std::span<const Bvh* const>(trees), blasBuilds, tlases, tlasBuilds, instanceBlas,
                            instancePose, poses, flattenedObjects);
}

std::vector<uint8_t> encodeTwoLevelFile(std::span<const Bvh* const> blases, std::span<const BvhBuildInfo> blasBuilds,
                                        std::span<const Bvh> tlases, std::span<const BvhBuildInfo> tlasBuilds,
                                        std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                        std::span<const TwoLevelPoseRecord> poses,
                                        std::span<const uint32_t> flattenedObjects) {
  std::vector<uint32_t> tlasInstances;
  for (const Bvh& t : tlases) tlasInstances.push_back(t.primCount());
  requireEncodable(blases.size(), blasBuilds.size(), tlasInstances, tlasBuilds, instanceBlas, instancePose, poses,
                   flattenedObjects);
  std::vector<FlatBvh> flat(blases.size() + tlases.size());
  forEachConcurrently(flat.size(), [&](std::size_t b) {
    flat[b] = flattenBvh(b < blases.size() ? *blases[b] : tlases[b - blases.size()]);
  });
  std::vector<const FlatBvh*> flatBlases, flatTlases;
  for (std::size_t b = 0; b < flat.size(); ++b) (b < blases.size() ? flatBlases : flatTlases).push_back(&flat[b]);
  return encodedParts(flatBlases, blasBuilds, flatTlases, tlasBuilds, instanceBlas, instancePose, poses,
                      flattenedObjects)
      .bytes();
}

TwoLevelFileParts twoLevelFileParts(std::span<const FlatBvh* const> blases, std::span<const BvhBuildInfo> blasBuilds,
                                    std::span<const FlatBvh* const> tlases, std::span<const BvhBuildInfo> tlasBuilds,
                                    std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                    std::span<const TwoLevelPoseRecord> poses,
                                    std::span<const uint32_t> flattenedObjects) {
  std::vector<uint32_t> tlasInstances;
  for (const FlatBvh* t : tlases) tlasInstances.push_back(t->triangleCount());
  requireEncodable(blases.size(), blasBuilds.size(), tlasInstances, tlasBuilds, instanceBlas, instancePose, poses,
                   flattenedObjects);
  return encodedParts(blases, blasBuilds, tlases, tlasBuilds, instanceBlas, instancePose, poses, flattenedObjects);
}

TwoLevelFile decodeTwoLevelFile(std::span<const uint8_t> bytes, const std::string& file) {
  ByteReader r(bytes, file);
  if (r.read<std::array<char, 8>>("magic") != detail::kTbvhMagic) r.fail("not a .tbvh file (bad magic)");
  const auto version = r.read<uint32_t>("version");
  if (version != kTbvhTwoLevelVersion)
    r.fail("is a .tbvh version " + std::to_string(version) + " file, not a two-level scene (version 3)");
  if (r.read<uint32_t>("header size") != kTbvhTwoLevelHeaderBytes)
    r.fail("two-level header size is not " + std::to_string(kTbvhTwoLevelHeaderBytes));
  const auto blasCount = r.read<uint32_t>("BLAS count");
  const auto instanceCount = r.read<uint32_t>("instance count");
  const auto poseCount = r.read<uint32_t>("pose count");
  const auto flattenedCount = r.read<uint32_t>("flattened object count");
  bool reservedZero = true;
  const auto timeStart = r.read<double>("time start");
  const auto timeEnd = r.read<double>("time end");
  const auto tlasWord = r.read<uint32_t>("TLAS count");
  for (int i = 0; i < 3; ++i) reservedZero = r.read<uint32_t>("reserved") == 0 && reservedZero;
  if (!reservedZero) r.fail("reserved header words must be 0");
  if (tlasWord == 1) r.fail("TLAS count 1 is written 0");
  if (tlasWord > kTbvhTwoLevelMaxTlas)
    r.fail("TLAS count " + std::to_string(tlasWord) + " exceeds " + std::to_string(kTbvhTwoLevelMaxTlas));
  const uint32_t tlasCount = tlasWord == 0 ? 1 : tlasWord;

  // Counts against the byte count before any allocation.
  if (blasCount == 0 || blasCount > kTbvhTwoLevelMaxBlas)
    r.fail("BLAS count " + std::to_string(blasCount) + " is not in 1.." + std::to_string(kTbvhTwoLevelMaxBlas));
  if (instanceCount == 0 || instanceCount > kMaxGpuTriangles)
    r.fail("instance count " + std::to_string(instanceCount) + " is not in 1.." + std::to_string(kMaxGpuTriangles));
  if (poseCount > instanceCount)
    r.fail("pose count " + std::to_string(poseCount) + " exceeds the instance count " + std::to_string(instanceCount));
  if (flattenedCount > kTbvhTwoLevelMaxFlattened)
    r.fail("flattened object count " + std::to_string(flattenedCount) + " exceeds " +
           std::to_string(kTbvhTwoLevelMaxFlattened));
  const uint32_t trees = blasCount + tlasCount;
  const uint64_t tables = tablesEnd(trees, instanceCount, poseCount, flattenedCount);
  if (bytes.size() < tables + uint64_t(trees) * kMinTreeBytes + 4)
    r.fail("file size " + std::to_string(bytes.size()) + " is too small for " + std::to_string(blasCount) +
           " BLAS, " + std::to_string(tlasCount) + " TLAS, " + std::to_string(instanceCount) + " instances, " +
           std::to_string(poseCount) + " poses and " + std::to_string(flattenedCount) + " flattened objects");
  const std::size_t crcOffset = bytes.size() - 4;
  uint32_t storedCrc;
  std::memcpy(&storedCrc, bytes.data() + crcOffset, 4);
  if (crc32(bytes.data(), crcOffset) != storedCrc) r.fail("checksum mismatch (the file is corrupt)");
  if (!std::isfinite(timeStart) || !std::isfinite(timeEnd) || timeEnd < timeStart)
    r.fail("time range must be finite and ordered");

  TwoLevelFile out;
  out.instanceBlas.resize(instanceCount);
  out.instancePose.resize(instanceCount);
  for (uint32_t i = 0; i < instanceCount; ++i) {
    out.instanceBlas[i] = r.read<uint32_t>("instance BLAS");
    out.instancePose[i] = r.read<uint32_t>("instance pose");
  }
  out.poses.resize(poseCount);
  for (TwoLevelPoseRecord& p : out.poses) {
    p.blas = r.read<uint32_t>("pose BLAS");
    p.outside = r.read<uint32_t>("pose outside");
    p.offset = r.read<double>("pose offset");
    p.speed = r.read<double>("pose speed");
  }
  if (auto problem = validateTwoLevelTables(blasCount, out.instanceBlas, out.instancePose, out.poses)) r.fail(*problem);
  out.flattenedObjects.resize(flattenedCount);
  for (uint32_t& o : out.flattenedObjects) o = r.read<uint32_t>("flattened object");
  if (auto problem = validateFlattenedObjects(out.flattenedObjects)) r.fail(*problem);

  const auto treeName = [&](uint32_t s) {
    return s >= blasCount ? "TLAS " + std::to_string(s - blasCount) : "BLAS " + std::to_string(s);
  };
  std::vector<std::pair<uint64_t, uint64_t>> entries(trees);
  uint64_t expected = align16(tables);
  for (uint32_t s = 0; s < trees; ++s) {
    auto& [offset, size] = entries[s];
    offset = r.read<uint64_t>("tree offset");
    size = r.read<uint64_t>("tree size");
    const std::string which = treeName(s);
    if (offset != expected)
      r.fail(which + " starts at byte " + std::to_string(offset) + ", expected " + std::to_string(expected));
    if (size < kMinTreeBytes || size > crcOffset - std::min<uint64_t>(expected, crcOffset))
      r.fail(which + " size " + std::to_string(size) + " does not fit the file");
    expected = align16(offset + size);
  }
  if (entries.back().first + entries.back().second != crcOffset)
    r.fail("the last TLAS does not end where the checksum starts");
  for (uint64_t b = tables; b < entries[0].first; ++b)
    if (bytes[b] != 0) r.fail("padding before BLAS 0 must be 0");
  for (uint32_t s = 0; s + 1 < trees; ++s)
    for (uint64_t b = entries[s].first + entries[s].second; b < entries[s + 1].first; ++b)
      if (bytes[b] != 0) r.fail("padding after tree " + std::to_string(s) + " must be 0");

  for (uint32_t s = 0; s < trees; ++s) {
    const bool isTlas = s >= blasCount;
    const std::string which = treeName(s);
    const auto image = bytes.subspan(entries[s].first, entries[s].second);
    uint32_t innerVersion;
    std::memcpy(&innerVersion, image.data() + 8, 4);
    if (innerVersion != kTbvhVersion) r.fail(which + " is not a version 1 tree");
    BvhBuildInfo build;
    FlatBvh tree = decodeFlatBvhFile(image, file + " (" + which + ")", &build);
    if (isTlas) {
      if (build.triangleCount != instanceCount)
        r.fail(which + " holds " + std::to_string(build.triangleCount) + " instances, the table " + std::to_string(instanceCount));
      out.tlases.push_back(std::move(tree));
      out.tlasBuilds.push_back(std::move(build));
    } else {
      out.blases.push_back(std::move(tree));
      out.blasBuilds.push_back(std::move(build));
    }
  }
  if (auto problem = validateTlasRanges(out.tlasBuilds, timeStart, timeEnd)) r.fail(*problem);
  return out;
}

}  // namespace tsah
