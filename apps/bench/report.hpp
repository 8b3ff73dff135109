#pragma once
// Turning results.json into results.md and PNG plots. Everything here reads the JSON alone, so
// `tsah bench --report-only DIR` can redo the report of a run made elsewhere (the GPU machine has
// no gnuplot).
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace tsah::bench {

// results.md: machine, options, commands, then per scene Table 1 and Table 2 (with the paper's
// figures beside them where results.json holds them), the segmenting experiment, the Embree
// comparison with a sentence on where each wins, and links to the plots listed in results["plots"].
std::string renderMarkdown(const nlohmann::json& results);

// The motion-blur part (results.json's scene.motion_blur) as Markdown: one scene's table with the
// agreement and the ratios, and one table across scenes (empty when no scene has the part). The
// command prints the second to stdout too.
std::string motionBlurSection(const nlohmann::json& scene);
std::string motionBlurSummary(const nlohmann::json& scenes);

// The two-level part (results.json's scene.two_level) as Markdown: one scene file's table with the
// optimization, agreement and ratios, and one table across scenes (empty when no scene has it).
std::string twoLevelSection(const nlohmann::json& scene);
std::string twoLevelSummary(const nlohmann::json& scenes);

struct PlotOutcome {
  bool made = false;
  std::string status;               // "gnuplot 5.4 patchlevel 4" or why plots were skipped
  std::vector<std::string> files;   // PNGs relative to the output folder
};

// Writes per scene plots/<scene>-cost.png (cost per evaluation frame per method: the paper's
// Figure 4 left), -convergence.png (average cost against optimization time for the three node
// selections: Figure 3), -total.png and -speed.png (total frame time and trace speed per frame per
// runtime method: Figures 5 and 6) and, with Embree results, -embree.png; each from a data file and
// a gnuplot script kept next to it. Skipped (with the reason in status) when gnuplot is missing.
PlotOutcome makePlots(const nlohmann::json& results, const std::filesystem::path& outDir);

// "gnuplot 5.4 patchlevel 4", or empty when gnuplot cannot be run.
std::string gnuplotVersion();

// Number formatting of the report: costs and seconds with 2 decimals, milliseconds and rates with
// 3 significant digits or more ("0.0412", "3.85", "41.2", "412", "4120").
std::string formatFixed(double value, int decimals);
std::string formatSignificant(double value);

// Reading a part of results.json (the motion-blur and two-level parts): a number field (0 when
// absent), the method of a part's "methods" with this name (null when absent), a method's average
// rate over all rays, and an agreement object (motion_bench.hpp's toJson) as "99.998%", with
// details "99.998% (3 of 1234 rays differ: 2 ties, 0 one misses, 1 other depth, 0 occlusion)".
double numberField(const nlohmann::json& j, const char* key);
const nlohmann::json* methodNamed(const nlohmann::json& part, const std::string& name);
double averageRate(const nlohmann::json& method);
std::string agreementText(const nlohmann::json& agreement, bool details);

}  // namespace tsah::bench
