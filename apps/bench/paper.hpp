#pragma once
// The T-SAH paper's own figures (Bittner & Meister, EG 2015, Tables 1 and 2) for the scenes that
// are in the benchmark data too, so the report can show them beside the measured ones.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace tsah::bench {

// Where the numbers come from (quoted in the report).
inline constexpr const char* kPaperSource =
    "J. Bittner and D. Meister, \"T-SAH: Animation Optimized Bounding Volume Hierarchies\", "
    "Computer Graphics Forum 34(2), Eurographics 2015, Table 1 (single-threaded C++ on an Intel Xeon "
    "E5-1620 3.6 GHz; cT = 3, cI = 2; 5 representative, 50 evaluation frames) and Table 2 (CUDA on an "
    "NVIDIA GeForce GTX TITAN Black; 1024x768, 1 primary + 8 AO + 2 shadow rays per pixel)";

// One row of Table 1: build ("test time") in seconds, average and maximum cost.
struct PaperCostRow {
  std::string method;  // the bench's method ids: rebuild, sahstar, sah0, tsah0, tsah2, tsah4
  double buildSeconds = 0.0, average = 0.0, maximum = 0.0;
};

// One row of Table 2: BVH update ms, trace speed MRays/s, total frame ms.
struct PaperRuntimeRow {
  std::string method;  // rebuild, sahstar, sah0, tsah0, lbvh (the paper's HLBVH-med), hlbvh-sah
  double updateMs = 0.0, mraysPerSecond = 0.0, totalMs = 0.0;
};

struct PaperScene {
  std::string paperName;          // as the paper writes it (BART Robots)
  std::vector<std::string> names; // bench scene names it matches (robot, robots)
  uint32_t triangles = 0;         // the paper's triangle count (rounded there: 71.5k)
  // The same scene as the data's: compare side by side. False where the paper used another version
  // (BART Museum: a higher detail level than the data's level 5), so only context.
  bool sameScene = true;
  std::vector<PaperCostRow> table1;
  std::vector<PaperRuntimeRow> table2;
  // BART Museum*: the paper's three trees, each optimized for a third of the animation.
  std::vector<PaperRuntimeRow> table2Segmented;
};

const std::vector<PaperScene>& paperScenes();

// The paper's scene for a bench scene name (case-insensitive) whose triangle count is within 2% of
// the paper's (so a different version of the scene is not compared as if it were the same); with
// sameSceneOnly false, also scenes the paper measured in another version.
const PaperScene* findPaperScene(const std::string& sceneName, uint32_t triangles, bool sameSceneOnly = true);

// The scene's figures as JSON for results.json: {paper_name, triangles, same_scene, source,
// table1: [{method, build_s, average, maximum}], table2: [{method, update_ms, mrays_per_s,
// total_ms}], table2_segmented (Museum* only)}.
nlohmann::json paperJson(const PaperScene& scene);

}  // namespace tsah::bench
