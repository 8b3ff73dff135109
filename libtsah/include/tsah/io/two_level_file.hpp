#pragma once
// The two-level .tbvh file (version 3, docs/tbvh-format.md): every BLAS and the TLAS trees of a
// two-level scene (one, or one per consecutive part of its time) as complete version 1 images, the
// instance table (each instance's BLAS and pose), the pose table, and the scene objects flattened
// into one source. The placements, paths and sources themselves stay in the scene file; the scene
// room (tsah/scene/two_level.hpp) checks a file against its scene.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah {

inline constexpr uint32_t kTbvhTwoLevelVersion = 3;
inline constexpr uint32_t kTbvhTwoLevelHeaderBytes = 64;
inline constexpr uint32_t kTbvhTwoLevelMaxBlas = 1u << 20;
inline constexpr uint32_t kTbvhNoPose = 0xffffffffu;
inline constexpr uint32_t kTbvhTwoLevelMaxFlattened = 0x7fffffffu;
inline constexpr uint32_t kTbvhTwoLevelMaxTlas = 4096;

// A pose as stored: the BLAS and the time mapping (offset, speed >= 0, outside 0 = hold, 1 = loop).
struct TwoLevelPoseRecord {
  uint32_t blas = 0;
  uint32_t outside = 0;
  double offset = 0.0, speed = 1.0;
  bool operator==(const TwoLevelPoseRecord&) const = default;
};

struct TwoLevelFile {
  std::vector<FlatBvh> blases;            // canonical trees with their stored box sets
  std::vector<BvhBuildInfo> blasBuilds;   // one per BLAS
  // The TLAS trees in time order (slots hold instance ids), each with its header: triangleCount =
  // instances, its time range the part where it is used (one tree: the scene's). Parts touch.
  std::vector<FlatBvh> tlases;
  std::vector<BvhBuildInfo> tlasBuilds;
  std::vector<uint32_t> instanceBlas;     // per instance
  std::vector<uint32_t> instancePose;     // per instance: a pose, or kTbvhNoPose (static BLAS)
  std::vector<TwoLevelPoseRecord> poses;
  // Scene objects flattened into one source (anim::flattenObjects), increasing; empty: none.
  std::vector<uint32_t> flattenedObjects;
};

// Checks the tables' rules (docs/tbvh-format.md, version 3): at least one BLAS and one instance,
// references in range, a pose's BLAS equal to its instances' BLAS, the instances of one BLAS
// either all posed (an animated source) or none, every pose used, pose fields finite (speed >= 0,
// outside 0 or 1). Returns the first violation.
std::optional<std::string> validateTwoLevelTables(uint32_t blasCount, std::span<const uint32_t> instanceBlas,
                                                  std::span<const uint32_t> instancePose,
                                                  std::span<const TwoLevelPoseRecord> poses);
// Checks the TLAS trees' time ranges: 1..kTbvhTwoLevelMaxTlas of them, finite, each start < end
// (a single one: start <= end), each part starting where the one before ends, the first at
// `start` and the last at `end` (the header's). Returns the first violation.
std::optional<std::string> validateTlasRanges(std::span<const BvhBuildInfo> tlasBuilds, double start, double end);

// Writes the version 3 file. Throws tsah::DataError when the tables break the rules above, the
// flattened object ids are not increasing, a TLAS does not hold one primitive per instance, the
// TLAS trees' time ranges are not consecutive touching parts (validateTlasRanges), or a tree cannot
// be encoded (encodeBvhFile).
std::vector<uint8_t> encodeTwoLevelFile(std::span<const Bvh> blases, std::span<const BvhBuildInfo> blasBuilds,
                                        std::span<const Bvh> tlases, std::span<const BvhBuildInfo> tlasBuilds,
                                        std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                        std::span<const TwoLevelPoseRecord> poses,
                                        std::span<const uint32_t> flattenedObjects = {});
// The same over trees held elsewhere (no copy of them); the trees are encoded concurrently.
std::vector<uint8_t> encodeTwoLevelFile(std::span<const Bvh* const> blases, std::span<const BvhBuildInfo> blasBuilds,
                                        std::span<const Bvh> tlases, std::span<const BvhBuildInfo> tlasBuilds,
                                        std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                        std::span<const TwoLevelPoseRecord> poses,
                                        std::span<const uint32_t> flattenedObjects = {});
// The same file as its parts in file order (the header and tables, then each tree image after its
// padding, then the checksum) over flattened trees (flattenBvh's) that the caller keeps: written
// one after the other they are encodeTwoLevelFile's bytes, never assembled in memory. Its images:
// every BLAS, then the TLAS trees.
using TwoLevelFileParts = TreeImagesFileParts;
TwoLevelFileParts twoLevelFileParts(std::span<const FlatBvh* const> blases, std::span<const BvhBuildInfo> blasBuilds,
                                    std::span<const FlatBvh* const> tlases, std::span<const BvhBuildInfo> tlasBuilds,
                                    std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                    std::span<const TwoLevelPoseRecord> poses,
                                    std::span<const uint32_t> flattenedObjects = {});
// Reads a version 3 file, validating everything before use (every tree as a version 1 file);
// throws tsah::FileError naming `file`. Allocates only after the counts have been checked against
// the byte count.
TwoLevelFile decodeTwoLevelFile(std::span<const uint8_t> bytes, const std::string& file);

}  // namespace tsah
