#include "bench/paper.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace tsah::bench {

const std::vector<PaperScene>& paperScenes() {
  // Transcribed from the paper's Tables 1 and 2 (see kPaperSource).
  static const std::vector<PaperScene> scenes = {
      {"BART Robots",
       {"robot", "robots", "bart-robots"},
       71500,
       true,
       {{"rebuild", 24.7, 56, 57},
        {"sahstar", 18.5, 57, 58},
        {"sah0", 0.4, 69, 71},
        {"tsah0", 1.9, 57, 57},
        {"tsah2", 1.9, 57, 57},
        {"tsah4", 2.0, 57, 57}},
       {{"rebuild", 0.0, 179.8, 64.8},
        {"sahstar", 7.4, 183.1, 70.7},
        {"sah0", 3.8, 190.1, 66.3},
        {"tsah0", 7.1, 190.7, 68.2},
        {"lbvh", 18.1, 117.0, 119.7},
        {"hlbvh-sah", 49.3, 129.4, 139.0}},
       {}},
      {"BART Kitchen",
       {"kitchen", "bart-kitchen"},
       110500,
       true,
       {{"rebuild", 41.6, 26, 26},
        {"sahstar", 32.6, 26, 26},
        {"sah0", 0.7, 37, 38},
        {"tsah0", 3.6, 26, 26},
        {"tsah2", 3.7, 26, 26},
        {"tsah4", 3.7, 26, 26}},
       {{"rebuild", 0.0, 241.6, 48.6},
        {"sahstar", 5.2, 241.1, 53.3},
        {"sah0", 3.4, 235.5, 54.5},
        {"tsah0", 5.3, 239.1, 53.8},
        {"lbvh", 17.4, 172.3, 87.8},
        {"hlbvh-sah", 46.2, 189.2, 107.7}},
       {}},
      {"BART Museum",
       {"museum", "museum5", "bart-museum"},
       75800,
       false,
       {{"rebuild", 39.7, 40, 148},
        {"sahstar", 18.6, 364, 1376},
        {"sah0", 0.4, 1558, 2335},
        {"tsah0", 123, 119, 365},
        {"tsah2", 155, 136, 282},
        {"tsah4", 161, 149, 266}},
       {{"rebuild", 0.0, 184.9, 70.9},
        {"sahstar", 2.3, 19.5, 674.5},
        {"sah0", 2.3, 6.3, 2082.4},
        {"tsah0", 2.7, 62.7, 212.0},
        {"lbvh", 10.3, 161.3, 91.7},
        {"hlbvh-sah", 22.6, 177.9, 96.5}},
       {{"rebuild", 0.0, 184.9, 70.9},
        {"sahstar", 2.4, 56.0, 234.1},
        {"sah0", 2.1, 6.7, 1958.0},
        {"tsah0", 2.1, 118.3, 110.8},
        {"lbvh", 10.3, 161.3, 91.7},
        {"hlbvh-sah", 22.6, 177.9, 96.5}}},
  };
  return scenes;
}

const PaperScene* findPaperScene(const std::string& sceneName, uint32_t triangles, bool sameSceneOnly) {
  std::string name = sceneName;
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const PaperScene& s : paperScenes()) {
    if (std::find(s.names.begin(), s.names.end(), name) == s.names.end()) continue;
    if (s.sameScene) {
      // The paper rounds to 0.1k triangles: within 2% is the same scene, anything else is not.
      if (std::fabs(double(triangles) - double(s.triangles)) > 0.02 * double(s.triangles)) return nullptr;
      return &s;
    }
    return sameSceneOnly ? nullptr : &s;
  }
  return nullptr;
}

nlohmann::json paperJson(const PaperScene& scene) {
  auto runtime = [](const std::vector<PaperRuntimeRow>& rows) {
    nlohmann::json out = nlohmann::json::array();
    for (const PaperRuntimeRow& r : rows)
      out.push_back({{"method", r.method}, {"update_ms", r.updateMs}, {"mrays_per_s", r.mraysPerSecond}, {"total_ms", r.totalMs}});
    return out;
  };
  nlohmann::json j;
  j["paper_name"] = scene.paperName;
  j["triangles"] = scene.triangles;
  j["same_scene"] = scene.sameScene;
  j["source"] = kPaperSource;
  j["table1"] = nlohmann::json::array();
  for (const PaperCostRow& r : scene.table1)
    j["table1"].push_back({{"method", r.method}, {"build_s", r.buildSeconds}, {"average", r.average}, {"maximum", r.maximum}});
  j["table2"] = runtime(scene.table2);
  if (!scene.table2Segmented.empty()) j["table2_segmented"] = runtime(scene.table2Segmented);
  return j;
}

}  // namespace tsah::bench
