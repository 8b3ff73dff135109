#pragma once
// The .tbvh file: an optimized BVH in a GPU-ready layout plus how it was built.
// Specified in docs/tbvh-format.md (byte layout, validation rules, checksum).
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/core/objective.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah {

inline constexpr uint32_t kTbvhVersion = 1;
inline constexpr uint32_t kTbvhLayoutAilaLaine64 = 1;  // GpuBvhNode, 64 bytes, see gpu_layout.hpp
inline constexpr uint32_t kTbvhHeaderBytes = 160;
inline constexpr std::size_t kTbvhNameBytes = 16;     // method and selection: NUL-padded ASCII

// How a tree was built; stored in the file header and printed by `tsah info`.
struct BvhBuildInfo {
  std::string method = "tsah";      // tsah, sah0, sahstar, ... (at most 15 printable ASCII chars)
  std::string selection = "mh";     // node selection of the optimizer: mh, random, batch, none
  uint32_t representativeFrames = 1;
  uint64_t seed = 0;
  Objective objective;              // k, cT, cI and the maximum leaf size the tree was built for
  double buildSeconds = 0.0;
  double timeStart = 0.0, timeEnd = 0.0;  // time range of the animation the tree was built for
  uint32_t triangleCount = 0;       // 0 when encoding: taken from the tree
  uint32_t vertexCount = 0;
  uint32_t topologyHash = 0;        // topologyHash(indices): catches a mismatched input
};

struct BvhFile {
  BvhBuildInfo info;
  Bvh bvh;  // topology, primIds and the boxes stored in the file (frameCount boxes per node)
};

// CRC-32 of the triangle index array (3 x uint32 per triangle, little-endian): the topology hash
// stored in .tbvh files and checked by `tsah trace` / `tsah export` against the animation.
uint32_t topologyHash(std::span<const uint32_t> indices);

// Writes the tree in canonical order (see flat_bvh.hpp). Throws tsah::DataError when the tree is
// empty or invalid or info.triangleCount disagrees with the tree, tsah::ConfigError when a name
// does not fit.
std::vector<uint8_t> encodeBvhFile(const Bvh& bvh, const BvhBuildInfo& info);
// The same file as its parts in file order (header, node blocks, root boxes, triangle indices,
// checksum) over a flattened tree (flattenBvh's) that the caller keeps: written one after the
// other they are encodeBvhFile's bytes, never assembled in memory. Throws as encodeBvhFile.
struct BvhFileParts {
  const FlatBvh* flat = nullptr;
  std::vector<uint8_t> header;
  uint32_t crc = 0;  // the file's checksum: over every part before it
  std::array<std::span<const uint8_t>, 5> parts() const;
  uint64_t size() const;
  uint32_t wholeCrc() const;  // crc32 of the whole file, its checksum included
};
BvhFileParts bvhFileParts(const FlatBvh& flat, const BvhBuildInfo& info);
// A container of tree images (the tree set's and the two-level file's) as its parts in file order:
// its header and tables, then each image at the next multiple of 16 bytes (zero padding before
// it), then the checksum over everything before it. seal() computes that checksum from the tables'
// and each image's own (crc32Combine): no byte of a tree is read twice.
struct TreeImagesFileParts {
  std::vector<uint8_t> tables;
  std::vector<BvhFileParts> images;
  uint32_t crc = 0;
  void seal();
  std::vector<std::span<const uint8_t>> parts() const;
  std::vector<uint8_t> bytes() const;  // the parts joined: the whole file
};
// Validates everything before use (magic, version, layout, sizes vs byte count, checksum, indices in
// range, each triangle referenced exactly once, the node graph a tree); throws tsah::FileError
// naming `file`. Allocates only after the counts have been checked against the byte count.
BvhFile decodeBvhFile(std::span<const uint8_t> bytes, const std::string& file);
// The same, returning the flat (GPU-ready) form without converting it back to a Bvh.
FlatBvh decodeFlatBvhFile(std::span<const uint8_t> bytes, const std::string& file, BvhBuildInfo* info = nullptr);

void saveBvhFile(const std::string& path, const Bvh& bvh, const BvhBuildInfo& info);  // atomic
BvhFile loadBvhFile(const std::string& path);

}  // namespace tsah
