// Fuzz entries for tree files: the version 1 .tbvh reader, the tree-set reader (versions 1 and 2)
// and the two-level reader (version 3).
// Byte 0 of an input selects checksum repairs, so mutations get past the CRCs to the structural
// checks behind them; the rest is the file.
#include <cstring>
#include <stdexcept>
#include <vector>

#include "tsah/base/binary_io.hpp"
#include "entries.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/io/two_level_file.hpp"

namespace tsah::fuzz {

namespace {

uint64_t readU64(const std::vector<uint8_t>& b, std::size_t at) {
  uint64_t v = 0;
  std::memcpy(&v, b.data() + at, 8);
  return v;
}

uint32_t readU32(const std::vector<uint8_t>& b, std::size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

// Sets the last 4 bytes of bytes[begin, begin + size) to the CRC-32 of the bytes before them.
void repairCrc(std::vector<uint8_t>& bytes, uint64_t begin, uint64_t size) {
  if (size < 4 || begin > bytes.size() || size > bytes.size() - begin) return;
  const uint32_t crc = tsah::crc32(bytes.data() + begin, size - 4);
  std::memcpy(bytes.data() + begin + size - 4, &crc, 4);
}

void requireValidSet(const TreeSet& set) {
  if (set.size() == 0 || set.ranges.size() != set.size() || set.builds.size() != set.size())
    throw std::logic_error("treeset: accepted a set whose trees, ranges and builds disagree");
  if (const auto problem = validateTimeRanges(set.ranges)) throw std::logic_error("treeset: accepted ranges: " + *problem);
  for (const FlatBvh& tree : set.trees)
    if (const auto problem = validateFlatBvh(tree)) throw std::logic_error("treeset: accepted a broken tree: " + *problem);
}

}  // namespace

void tbvh(std::span<const uint8_t> data) {
  if (data.empty()) return;
  std::vector<uint8_t> bytes(data.begin() + 1, data.end());
  if (data[0] & 1) repairCrc(bytes, 0, bytes.size());
  refuseCleanly([&] {
    const BvhFile file = decodeBvhFile(bytes, "fuzz.tbvh");
    if (const auto problem = validate(file.bvh)) throw std::logic_error("tbvh: accepted a broken tree: " + *problem);
    // An accepted file is canonical: writing it again gives the same bytes.
    if (encodeBvhFile(file.bvh, file.info) != bytes) throw std::logic_error("tbvh: accepted file does not re-encode");
  });
}

void treeset(std::span<const uint8_t> data) {
  if (data.empty()) return;
  std::vector<uint8_t> bytes(data.begin() + 1, data.end());
  // Bit 1: repair each tree's own CRC as the table places it; bit 0: then the set's CRC.
  if ((data[0] & 2) && bytes.size() >= kTbvhSetHeaderBytes && readU32(bytes, 8) == kTbvhSetVersion) {
    const uint64_t count = readU32(bytes, 20);
    for (uint64_t s = 0; s < count && kTbvhSetHeaderBytes + (s + 1) * kTbvhSetEntryBytes <= bytes.size(); ++s) {
      const std::size_t entry = kTbvhSetHeaderBytes + s * kTbvhSetEntryBytes;
      repairCrc(bytes, readU64(bytes, entry + 16), readU64(bytes, entry + 24));
    }
  }
  if (data[0] & 1) repairCrc(bytes, 0, bytes.size());
  refuseCleanly([&] {
    const TreeSet set = decodeTreeSetFile(bytes, "fuzz.tbvh");
    requireValidSet(set);
    // A version 2 file that was accepted is canonical: the encoder writes the same bytes.
    if (set.version != kTbvhSetVersion) return;
    std::vector<Bvh> trees;
    for (const FlatBvh& tree : set.trees) trees.push_back(unflattenBvh(tree));
    if (encodeTreeSetFile(trees, set.builds, set.ranges, set.info) != bytes)
      throw std::logic_error("treeset: accepted file does not re-encode");
  });
}

void twolevel(std::span<const uint8_t> data) {
  if (data.empty()) return;
  std::vector<uint8_t> bytes(data.begin() + 1, data.end());
  // Bit 1: repair each tree's own CRC as the tree table places it; bit 0: then the file's CRC.
  if ((data[0] & 2) && bytes.size() >= kTbvhTwoLevelHeaderBytes && readU32(bytes, 8) == kTbvhTwoLevelVersion) {
    const uint32_t tlasCount = readU32(bytes, 48);  // 0: one TLAS
    const uint64_t trees = uint64_t(readU32(bytes, 16)) + (tlasCount == 0 ? 1 : tlasCount);
    const uint64_t table = kTbvhTwoLevelHeaderBytes + 8 * uint64_t(readU32(bytes, 20)) + 24 * uint64_t(readU32(bytes, 24)) +
                           4 * uint64_t(readU32(bytes, 28));
    for (uint64_t s = 0; s < trees && table + (s + 1) * 16 <= bytes.size(); ++s)
      repairCrc(bytes, readU64(bytes, table + s * 16), readU64(bytes, table + s * 16 + 8));
  }
  if (data[0] & 1) repairCrc(bytes, 0, bytes.size());
  refuseCleanly([&] {
    const TwoLevelFile file = decodeTwoLevelFile(bytes, "fuzz.tbvh");
    if (const auto problem = validateTwoLevelTables(uint32_t(file.blases.size()), file.instanceBlas, file.instancePose, file.poses))
      throw std::logic_error("twolevel: accepted tables: " + *problem);
    for (std::size_t k = 1; k < file.flattenedObjects.size(); ++k)
      if (file.flattenedObjects[k] <= file.flattenedObjects[k - 1])
        throw std::logic_error("twolevel: accepted flattened objects out of order");
    if (file.tlases.size() != file.tlasBuilds.size() || file.tlasBuilds.empty())
      throw std::logic_error("twolevel: accepted a file without one build record per TLAS");
    if (const auto problem = validateTlasRanges(file.tlasBuilds, file.tlasBuilds.front().timeStart,
                                                file.tlasBuilds.back().timeEnd))
      throw std::logic_error("twolevel: accepted TLAS ranges: " + *problem);
    std::vector<Bvh> blases;
    for (const FlatBvh& tree : file.blases) {
      if (const auto problem = validateFlatBvh(tree)) throw std::logic_error("twolevel: accepted a broken BLAS: " + *problem);
      blases.push_back(unflattenBvh(tree));
    }
    std::vector<Bvh> tlases;
    for (const FlatBvh& tree : file.tlases) {
      if (const auto problem = validateFlatBvh(tree)) throw std::logic_error("twolevel: accepted a broken TLAS: " + *problem);
      tlases.push_back(unflattenBvh(tree));
    }
    // An accepted file is canonical: the encoder writes the same bytes.
    if (encodeTwoLevelFile(blases, file.blasBuilds, tlases, file.tlasBuilds, file.instanceBlas, file.instancePose,
                           file.poses, file.flattenedObjects) != bytes)
      throw std::logic_error("twolevel: accepted file does not re-encode");
  });
}

}  // namespace tsah::fuzz
