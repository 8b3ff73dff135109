#pragma once
// The two-level .tbvh file (version 3, docs/tbvh-format.md): every BLAS and the TLAS of a
// two-level scene as complete version 1 images, the instance table (each instance's BLAS and pose)
// and the pose table, and the scene objects flattened into one source. The placements, paths and sources themselves stay in the scene file; the
// scene room (tsah/scene/two_level.hpp) checks a file against its scene.
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
  FlatBvh tlas;                           // slots hold instance ids
  BvhBuildInfo tlasBuild;                 // triangleCount = instances, its time range the scene's
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

// Writes the version 3 file. Throws tsah::DataError when the tables break the rules above, the
// flattened object ids are not increasing, the TLAS does not hold one primitive per instance, or a
// tree cannot be encoded (encodeBvhFile).
std::vector<uint8_t> encodeTwoLevelFile(std::span<const Bvh> blases, std::span<const BvhBuildInfo> blasBuilds,
                                        const Bvh& tlas, const BvhBuildInfo& tlasBuild,
                                        std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                        std::span<const TwoLevelPoseRecord> poses,
                                        std::span<const uint32_t> flattenedObjects = {});
// The same over trees held elsewhere (no copy of them); the trees are encoded concurrently.
std::vector<uint8_t> encodeTwoLevelFile(std::span<const Bvh* const> blases, std::span<const BvhBuildInfo> blasBuilds,
                                        const Bvh& tlas, const BvhBuildInfo& tlasBuild,
                                        std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                        std::span<const TwoLevelPoseRecord> poses,
                                        std::span<const uint32_t> flattenedObjects = {});
// The same file as its parts in file order (the header and tables, then each tree image after its
// padding, then the checksum) over flattened trees (flattenBvh's) that the caller keeps: written
// one after the other they are encodeTwoLevelFile's bytes, never assembled in memory. Its images:
// every BLAS, then the TLAS.
using TwoLevelFileParts = TreeImagesFileParts;
TwoLevelFileParts twoLevelFileParts(std::span<const FlatBvh* const> blases, std::span<const BvhBuildInfo> blasBuilds,
                                    const FlatBvh& tlas, const BvhBuildInfo& tlasBuild,
                                    std::span<const uint32_t> instanceBlas, std::span<const uint32_t> instancePose,
                                    std::span<const TwoLevelPoseRecord> poses,
                                    std::span<const uint32_t> flattenedObjects = {});
// Reads a version 3 file, validating everything before use (every tree as a version 1 file);
// throws tsah::FileError naming `file`. Allocates only after the counts have been checked against
// the byte count.
TwoLevelFile decodeTwoLevelFile(std::span<const uint8_t> bytes, const std::string& file);

}  // namespace tsah
