#pragma once
// `tsah bench --scaling`: how the optimizers scale with the triangle count. Every point is one
// `tsah optimize --json` child process (so its peak resident memory is the whole command's, as
// /usr/bin/time reports it): generated explode animations of several sizes and real scenes, for
// each optimizer. Results in OUT/scaling.json and OUT/scaling.md, plots in OUT/plots/scaling-*.png.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/data_scan.hpp"

namespace tsah::bench {

struct ScalingOptions {
  std::string program;                 // the tsah executable that runs each optimization
  std::vector<uint32_t> sizes{10000, 30000, 100000, 300000};  // generated explode triangles
  uint32_t keyframes = 10;             // keyframes of the generated animations
  // Optimizer names as `tsah optimize --optimizer` takes them, and "cuda" for `--device cuda` (the
  // bench adds it when a device is present and no list was given).
  std::vector<std::string> optimizers{"sequential", "parallel"};
  unsigned threads = 0;                // --threads of every optimization (0: all cores)
  uint32_t frames = 5, evalFrames = 10;
  uint64_t seed = 1;
};

// Generates the animations (cached in outDir/scaling/), runs every (input, optimizer) pair and
// returns {"rows": [...], "machine"...}: per row input, kind (generated or scene), triangles,
// optimizer, threads, optimize_s (the optimizer's own time), command_s and cpu_s of the whole
// process, peak_rss_bytes, bytes_per_triangle, initial_cost, final_cost (C~^k with one triangle
// per leaf), eval_average (Eq. 1 of the collapsed tree over evalFrames frames). Throws tsah::Failure
// when a child fails.
nlohmann::json runScaling(const std::vector<SceneSource>& scenes, const ScalingOptions& options,
                          const std::filesystem::path& outDir, const std::function<void(const std::string&)>& progress);

// scaling.md: the table per input with the parallel/sequential cost ratio, and the plot links.
std::string renderScalingMarkdown(const nlohmann::json& results);

// plots/scaling-time.png, -memory.png and -cost.png against the triangle count; the names of the
// files made go to results["plots"], the outcome to results["plot_status"].
void makeScalingPlots(nlohmann::json& results, const std::filesystem::path& outDir);

}  // namespace tsah::bench
