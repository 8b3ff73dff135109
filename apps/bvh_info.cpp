#include "bvh_info.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <unistd.h>

#include "anim/binary_io.hpp"
#include "anim/error.hpp"

namespace tsah::cli {

bool looksLikeBvhFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec) || std::filesystem::is_directory(path, ec)) return false;  // sequences
  const anim::InputFile in(path);  // a FIFO or device is refused here instead of blocking
  char magic[8] = {};
  return ::pread(in.fd(), magic, sizeof magic, 0) == ssize_t(sizeof magic) && std::string(magic, 7) == "TSAHBVH" &&
         magic[7] == '\0';
}

nlohmann::json describeBvh(const tsah::FlatBvh& flat, const tsah::BvhBuildInfo& info) {
  // Leaf sizes from the first node block (all blocks share the topology).
  uint32_t maxLeaf = flat.interiorCount == 0 ? flat.rootCount : 0;
  for (const GpuBvhNode& n : flat.frameNodes(0))
    for (int c = 0; c < 2; ++c)
      if (isLeafRef(n.childRef(c))) maxLeaf = std::max(maxLeaf, n.childCount(c));
  const Aabb& b = flat.rootBoxes[0];
  nlohmann::json j;
  j["format"] = "tbvh";
  j["version"] = kTbvhVersion;
  j["layout"] = "aila-laine-64";
  j["method"] = info.method;
  j["selection"] = info.selection;
  j["k"] = info.k;
  j["representative_frames"] = info.representativeFrames;
  j["seed"] = info.seed;
  j["ct"] = info.ct;
  j["ci"] = info.ci;
  j["max_leaf_size"] = info.maxLeafSize;
  j["build_s"] = info.buildSeconds;
  j["time"] = {info.timeStart, info.timeEnd};
  j["triangles"] = info.triangleCount;
  j["vertices"] = info.vertexCount;
  j["topology_hash"] = info.topologyHash;
  j["interior_nodes"] = flat.interiorCount;
  j["leaves"] = flat.leafCount;
  j["box_frames"] = flat.frameCount;
  j["depth"] = flat.depth;
  j["mean_leaf_size"] = flat.leafCount ? double(flat.triangleCount()) / flat.leafCount : 0.0;
  j["largest_leaf"] = maxLeaf;
  j["node_bytes"] = sizeof(GpuBvhNode);
  j["bounds_frame0"] = {{b.lo.x, b.lo.y, b.lo.z}, {b.hi.x, b.hi.y, b.hi.z}};
  return j;
}

void describeBvhFile(const std::string& path, bool json) {
  const std::vector<uint8_t> bytes = anim::readFile(path);
  BvhBuildInfo info;
  const FlatBvh flat = decodeFlatBvhFile(bytes, path, &info);
  nlohmann::json j = describeBvh(flat, info);
  j["file"] = path;
  j["file_bytes"] = bytes.size();
  if (json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  char hash[16];
  std::snprintf(hash, sizeof hash, "%08x", info.topologyHash);
  const auto& lo = j["bounds_frame0"][0];
  const auto& hi = j["bounds_frame0"][1];
  std::printf("file          %s (%zu bytes, .tbvh v%u, Aila-Laine 64-byte nodes)\n", path.c_str(), bytes.size(),
              kTbvhVersion);
  std::printf("method        %s (selection %s, k=%d, seed %llu)\n", info.method.c_str(), info.selection.c_str(), info.k,
              static_cast<unsigned long long>(info.seed));
  std::printf("cost          cT=%g cI=%g, max leaf size %u\n", double(info.ct), double(info.ci), info.maxLeafSize);
  std::printf("frames        %u representative, %u box sets, time %g .. %g\n", info.representativeFrames,
              flat.frameCount, info.timeStart, info.timeEnd);
  std::printf("triangles     %u (vertices %u, topology hash %s)\n", info.triangleCount, info.vertexCount, hash);
  std::printf("nodes         %u interior, %u leaves (mean %.2f, largest %u triangles), depth %u\n", flat.interiorCount,
              flat.leafCount, j["mean_leaf_size"].get<double>(), j["largest_leaf"].get<uint32_t>(), flat.depth);
  std::printf("bounds        (%.4g, %.4g, %.4g) .. (%.4g, %.4g, %.4g) in the first box set\n", lo[0].get<double>(),
              lo[1].get<double>(), lo[2].get<double>(), hi[0].get<double>(), hi[1].get<double>(), hi[2].get<double>());
  std::printf("build time    %.3f s\n", info.buildSeconds);
}

void checkTreeMatchesAnimation(const tsah::BvhBuildInfo& info, const std::string& bvhPath, const anim::Animation& a,
                               const std::string& animationPath) {
  auto fail = [&](const std::string& what) {
    throw anim::Error(bvhPath + " was not built for " + animationPath + ": " + what);
  };
  if (info.triangleCount != a.triangleCount())
    fail("the tree has " + std::to_string(info.triangleCount) + " triangles, the animation " +
         std::to_string(a.triangleCount()));
  if (info.vertexCount != a.vertexCount())
    fail("the tree was built for " + std::to_string(info.vertexCount) + " vertices, the animation has " +
         std::to_string(a.vertexCount()));
  const uint32_t hash = topologyHash(a.indices());
  if (info.topologyHash != hash) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "topology hash %08x, the animation's is %08x", info.topologyHash, hash);
    fail(std::string(buf) + " (same counts, different triangles)");
  }
}

}  // namespace tsah::cli
