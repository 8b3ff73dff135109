#pragma once
// The .tbvh file: an optimized BVH in a GPU-ready layout plus how it was built.
// Specified in docs/tbvh-format.md.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tsah/bvh.hpp"

namespace tsah {

// How a tree was built; stored in the file header and printed by `tsah info`.
struct BvhBuildInfo {
  std::string method = "tsah";      // tsah, sah0, sahstar, ...
  std::string selection = "mh";     // node selection of the optimizer: mh, random, batch, none
  int k = 0;                        // T-SAH exponent
  uint32_t representativeFrames = 1;
  uint64_t seed = 0;
  float ct = 3.0f, ci = 2.0f;       // cost constants
  uint32_t maxLeafSize = 8;
  double buildSeconds = 0.0;
  double timeStart = 0.0, timeEnd = 0.0;  // time range of the animation the tree was built for
  uint32_t triangleCount = 0;
  uint32_t vertexCount = 0;
  uint32_t topologyHash = 0;        // crc32 of the animation's index array: catches a mismatched input
};

struct BvhFile {
  BvhBuildInfo info;
  Bvh bvh;  // topology, primIds and the boxes stored in the file (frameCount boxes per node)
};

std::vector<uint8_t> encodeBvhFile(const Bvh& bvh, const BvhBuildInfo& info);
// Validates everything before use (magic, version, layout, sizes vs byte count, checksum, indices in
// range, each triangle referenced exactly once, the node graph a tree); throws anim::ImportError
// naming `file`.
BvhFile decodeBvhFile(std::span<const uint8_t> bytes, const std::string& file);

void saveBvhFile(const std::string& path, const Bvh& bvh, const BvhBuildInfo& info);  // atomic
BvhFile loadBvhFile(const std::string& path);

}  // namespace tsah
