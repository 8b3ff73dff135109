#include "bvh_info.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <unistd.h>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "animation_frames.hpp"
#include "cli.hpp"
#include "tsah/inspect/tree_quality.hpp"

namespace tsah::cli {

bool looksLikeBvhFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec) || std::filesystem::is_directory(path, ec)) return false;  // sequences
  const tsah::InputFile in(path);  // a FIFO or device is refused here instead of blocking
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
  j["k"] = info.objective.k;
  j["representative_frames"] = info.representativeFrames;
  j["seed"] = info.seed;
  j["ct"] = info.objective.cost.ct;
  j["ci"] = info.objective.cost.ci;
  j["max_leaf_size"] = info.objective.maxLeafSize;
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

namespace {

void printTree(const nlohmann::json& j, const tsah::BvhBuildInfo& info, const FlatBvh& flat) {
  char hash[16];
  std::snprintf(hash, sizeof hash, "%08x", info.topologyHash);
  const auto& lo = j["bounds_frame0"][0];
  const auto& hi = j["bounds_frame0"][1];
  std::printf("method        %s (selection %s, k=%d, seed %llu)\n", info.method.c_str(), info.selection.c_str(), info.objective.k,
              static_cast<unsigned long long>(info.seed));
  std::printf("cost          cT=%g cI=%g, max leaf size %u\n", double(info.objective.cost.ct), double(info.objective.cost.ci), info.objective.maxLeafSize);
  std::printf("frames        %u representative, %u box sets, time %g .. %g\n", info.representativeFrames,
              flat.frameCount, info.timeStart, info.timeEnd);
  std::printf("triangles     %u (vertices %u, topology hash %s)\n", info.triangleCount, info.vertexCount, hash);
  std::printf("nodes         %u interior, %u leaves (mean %.2f, largest %u triangles), depth %u\n", flat.interiorCount,
              flat.leafCount, j["mean_leaf_size"].get<double>(), j["largest_leaf"].get<uint32_t>(), flat.depth);
  std::printf("bounds        (%.4g, %.4g, %.4g) .. (%.4g, %.4g, %.4g) in the first box set\n", lo[0].get<double>(),
              lo[1].get<double>(), lo[2].get<double>(), hi[0].get<double>(), hi[1].get<double>(), hi[2].get<double>());
  std::printf("build time    %.3f s\n", info.buildSeconds);
}

}  // namespace

void describeBvhFile(const std::string& path, bool json) {
  const std::vector<uint8_t> bytes = tsah::readFile(path);
  const TreeSet set = decodeTreeSetFile(bytes, path);
  if (set.version == kTbvhVersion) {
    nlohmann::json j = describeBvh(set.trees[0], set.builds[0]);
    j["file"] = path;
    j["file_bytes"] = bytes.size();
    if (json) {
      std::printf("%s\n", j.dump().c_str());
      return;
    }
    std::printf("file          %s (%zu bytes, .tbvh v%u, Aila-Laine 64-byte nodes)\n", path.c_str(), bytes.size(),
                kTbvhVersion);
    printTree(j, set.builds[0], set.trees[0]);
    return;
  }
  nlohmann::json j;
  j["format"] = "tbvh-set";
  j["version"] = set.version;
  j["file"] = path;
  j["file_bytes"] = bytes.size();
  j["trees"] = set.size();
  j["segmentation"] = set.info.segmentation;
  j["overlap"] = set.info.overlap;
  if (set.info.budget > 0) j["budget"] = {{"value", set.info.budget}, {"relative", set.info.budgetRelative}};
  j["time"] = {set.ranges.front().start, set.ranges.back().end};
  j["parts"] = nlohmann::json::array();
  for (uint32_t s = 0; s < set.size(); ++s) {
    nlohmann::json p = describeBvh(set.trees[s], set.builds[s]);
    p["index"] = s;
    p["used"] = {s == 0 ? set.ranges[0].start : switchTime(set.ranges, s - 1),
                 s + 1 == set.size() ? set.ranges[s].end : switchTime(set.ranges, s)};
    j["parts"].push_back(p);
  }
  if (json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("file          %s (%zu bytes, .tbvh v%u tree set, Aila-Laine 64-byte nodes)\n", path.c_str(),
              bytes.size(), set.version);
  std::printf("set           %u trees, %s segmentation, time %g .. %g, overlap %g", set.size(),
              set.info.segmentation.c_str(), set.ranges.front().start, set.ranges.back().end, set.info.overlap);
  if (set.info.budget > 0)
    std::printf(", budget %g%s", set.info.budget, set.info.budgetRelative ? "x the per-frame optimized cost" : " (cost)");
  std::printf("\n");
  for (uint32_t s = 0; s < set.size(); ++s) {
    const nlohmann::json& p = j["parts"][s];
    std::printf("\ntree %u        used for t %g .. %g (the runtimes switch in the middle of an overlap)\n", s,
                p["used"][0].get<double>(), p["used"][1].get<double>());
    printTree(p, set.builds[s], set.trees[s]);
  }
}

}  // namespace tsah::cli

namespace tsah::cli {

namespace {

nlohmann::json treeQualityJson(const TreeShape& shape, const TreeQuality& quality, std::span<const double> times) {
  nlohmann::json j;
  j["shape"] = {{"interior_nodes", shape.innerCount}, {"leaves", shape.leafCount},
                {"depth", shape.depth},               {"smallest_leaf", shape.smallestLeaf},
                {"largest_leaf", shape.largestLeaf},  {"mean_leaf_size", shape.meanLeafSize},
                {"leaves_of_size", shape.leavesOfSize}};
  double sum = 0.0, largest = 0.0;
  nlohmann::json rows = nlohmann::json::array();
  for (std::size_t f = 0; f < quality.frames.size(); ++f) {
    const FrameQuality& q = quality.frames[f];
    rows.push_back({{"time", times[f]},
                    {"cost", q.cost.total()},
                    {"inner_cost", q.cost.inner()},
                    {"leaf_cost", q.cost.leaves()},
                    {"mean_leaf_depth", q.meanLeafDepth},
                    {"mean_leaf_size", q.meanLeafSize},
                    {"root_child_growth", {q.rootChildGrowth[0], q.rootChildGrowth[1]}}});
    sum += q.cost.total();
    largest = std::max(largest, q.cost.total());
  }
  j["frames"] = rows;
  j["average_cost"] = quality.frames.empty() ? 0.0 : sum / double(quality.frames.size());
  j["max_cost"] = largest;
  return j;
}

}  // namespace

namespace {

// One tree over the frames at `times` (frame numbers `frameNumbers` of the chosen frames): its
// shape and quality as JSON, with the tree's objective.
nlohmann::json qualityOver(const FlatBvh& flat, const BvhBuildInfo& info, const anim::Animation& a,
                           const std::vector<double>& times) {
  const Bvh bvh = unflattenBvh(flat);
  const TreeQuality quality = times.empty() ? TreeQuality{} : evaluateTreeQuality(bvh, animationFrames(a, times), info.objective.cost);
  nlohmann::json j = treeQualityJson(treeShape(bvh), quality, times);
  j["method"] = info.method;
  j["ct"] = info.objective.cost.ct;
  j["ci"] = info.objective.cost.ci;
  return j;
}

void printQuality(const nlohmann::json& j, const std::vector<uint32_t>& frameNumbers) {
  const auto& shape = j["shape"];
  std::printf("shape       %u interior, %u leaves, depth %u, leaves of %u..%u triangles (mean %.2f)\n",
              shape["interior_nodes"].get<uint32_t>(), shape["leaves"].get<uint32_t>(), shape["depth"].get<uint32_t>(),
              shape["smallest_leaf"].get<uint32_t>(), shape["largest_leaf"].get<uint32_t>(),
              shape["mean_leaf_size"].get<double>());
  std::string sizes;
  const auto& leavesOfSize = shape["leaves_of_size"];
  for (std::size_t s = 1; s < leavesOfSize.size(); ++s)
    if (leavesOfSize[s].get<uint64_t>()) sizes += "  " + std::to_string(s) + ":" + leavesOfSize[s].dump();
  std::printf("leaf sizes %s\n\n", sizes.c_str());
  std::printf("%6s %10s %9s %9s %9s %10s %9s %9s %9s\n", "frame", "time", "cost", "inner", "leaf", "leaf depth",
              "leaf size", "child 0", "child 1");
  for (std::size_t f = 0; f < j["frames"].size(); ++f) {
    const auto& q = j["frames"][f];
    std::printf("%6u %10.4g %9.3f %9.3f %9.3f %10.2f %9.2f %9.3f %9.3f\n", frameNumbers[f], q["time"].get<double>(),
                q["cost"].get<double>(), q["inner_cost"].get<double>(), q["leaf_cost"].get<double>(),
                q["mean_leaf_depth"].get<double>(), q["mean_leaf_size"].get<double>(),
                q["root_child_growth"][0].get<double>(), q["root_child_growth"][1].get<double>());
  }
  if (j["frames"].empty()) {
    std::printf("(none of the chosen frames falls in this tree's part)\n");
    return;
  }
  std::printf("\naverage cost %.3f, maximum %.3f (Eq. 1; child columns: area of the root's children over frame 0's)\n",
              j["average_cost"].get<double>(), j["max_cost"].get<double>());
}

}  // namespace

void describeTreeOverAnimation(const std::string& bvhPath, const std::string& animationPath, uint32_t frames,
                               bool json) {
  const TreeSet set = decodeTreeSetFile(tsah::readFile(bvhPath), bvhPath);
  const anim::Animation a = loadInput(animationPath);
  checkTreeMatchesAnimation(set.builds.front(), bvhPath, a, animationPath);
  const std::vector<double> times =
      frames ? a.uniformTimes(frames) : std::vector<double>(a.times().begin(), a.times().end());
  // Each tree over the frames it is used for (all of them for a single tree), as the runtimes switch.
  std::vector<std::vector<double>> partTimes(set.size());
  std::vector<std::vector<uint32_t>> partFrames(set.size());
  for (uint32_t f = 0; f < times.size(); ++f) {
    const uint32_t s = set.treeAt(times[f]);
    partTimes[s].push_back(times[f]);
    partFrames[s].push_back(f);
  }
  if (set.version == kTbvhVersion) {  // one tree
    const BvhBuildInfo& info = set.builds[0];
    nlohmann::json j = qualityOver(set.trees[0], info, a, times);
    j["tree"] = bvhPath;
    j["animation"] = animationPath;
    if (json) {
      std::printf("%s\n", j.dump().c_str());
      return;
    }
    std::printf("tree        %s (%s, k=%d, %u representative frames, cT=%g cI=%g)\n", bvhPath.c_str(),
                info.method.c_str(), info.objective.k, info.representativeFrames, double(info.objective.cost.ct),
                double(info.objective.cost.ci));
    std::printf("animation   %s (%zu frames evaluated, time %g .. %g)\n", animationPath.c_str(), times.size(),
                times.front(), times.back());
    printQuality(j, partFrames[0]);
    return;
  }
  nlohmann::json j;
  j["tree_set"] = bvhPath;
  j["animation"] = animationPath;
  j["trees"] = nlohmann::json::array();
  for (uint32_t s = 0; s < set.size(); ++s) {
    nlohmann::json p = qualityOver(set.trees[s], set.builds[s], a, partTimes[s]);
    p["index"] = s;
    p["used"] = {s == 0 ? set.ranges[0].start : switchTime(set.ranges, s - 1),
                 s + 1 == set.size() ? set.ranges[s].end : switchTime(set.ranges, s)};
    j["trees"].push_back(p);
  }
  if (json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("tree set    %s (%u trees)\n", bvhPath.c_str(), set.size());
  std::printf("animation   %s (%zu frames evaluated, time %g .. %g; each with the tree of its part)\n",
              animationPath.c_str(), times.size(), times.front(), times.back());
  for (uint32_t s = 0; s < set.size(); ++s) {
    const nlohmann::json& p = j["trees"][s];
    const BvhBuildInfo& info = set.builds[s];
    std::printf("\ntree %u      used for t %g .. %g (%s, k=%d, %u representative frames, cT=%g cI=%g)\n", s,
                p["used"][0].get<double>(), p["used"][1].get<double>(), info.method.c_str(), info.objective.k,
                info.representativeFrames, double(info.objective.cost.ct), double(info.objective.cost.ci));
    printQuality(p, partFrames[s]);
  }
}

}  // namespace tsah::cli
