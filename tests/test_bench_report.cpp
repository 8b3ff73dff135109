// results.json -> results.md and plots (bench/report.hpp), and the runtime JSON it reads
// (bench/runtime_bench.hpp toJson).
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include "bench/paper.hpp"
#include "bench/process.hpp"
#include "bench/report.hpp"
#include "bench/runtime_bench.hpp"
#include "test_support.hpp"

namespace {

using nlohmann::json;
using tsah::bench::formatSignificant;

TEST(BenchReport, NumberFormats) {
  EXPECT_EQ(formatSignificant(0.04123), "0.0412");
  EXPECT_EQ(formatSignificant(0.4123), "0.412");
  EXPECT_EQ(formatSignificant(3.854), "3.85");
  EXPECT_EQ(formatSignificant(41.25), "41.2");
  EXPECT_EQ(formatSignificant(412.4), "412");
  EXPECT_EQ(formatSignificant(0.0), "0");
  EXPECT_EQ(tsah::bench::formatFixed(56.5, 2), "56.50");
}

tsah::bench::FrameTiming frame(double t, double update, uint64_t rays, double ms) {
  tsah::bench::FrameTiming f;
  f.time = t;
  f.updateMs = update;
  f.rays.primary = {rays, ms / 2};
  f.rays.ao = {3 * rays, ms / 4};
  f.rays.shadow = {rays, ms / 4};
  f.traceMs = ms;
  f.totalMs = update + ms;
  return f;
}

TEST(BenchReport, RuntimeAveragesAreMeansOfTimesAndRatesOverAllRays) {
  tsah::bench::RuntimeMethod m{"tsah0", "T-SAH k=0 refit", "refit", {frame(0, 1, 1000, 2), frame(1, 3, 3000, 2)}, {}};
  const json j = tsah::bench::toJson(m);
  EXPECT_EQ(j["frames"], 2);
  EXPECT_DOUBLE_EQ(j["average"]["update_ms"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(j["average"]["total_ms"].get<double>(), 4.0);
  // All rays (5 x 4000) over all trace time (4 ms): 5 MRays/s, not the mean of the per-frame rates.
  EXPECT_DOUBLE_EQ(j["average"]["mrays_per_s"]["total"].get<double>(), 20000.0 / 4.0 / 1000.0);
  EXPECT_DOUBLE_EQ(j["average"]["mrays_per_s"]["primary"].get<double>(), 4000.0 / 2.0 / 1000.0);
  EXPECT_DOUBLE_EQ(j["average"]["rays_per_frame"]["ao"].get<double>(), 6000.0);
  EXPECT_EQ(j["per_frame"]["total_ms"].size(), 2u);
  EXPECT_DOUBLE_EQ(j["per_frame"]["mrays_per_s"][1].get<double>(), 15000.0 / 2.0 / 1000.0);
  EXPECT_FALSE(j.contains("extra"));
}

json runtimeMethod(const std::string& name, const std::string& label, double update, double rate, double total) {
  return {{"name", name},
          {"label", label},
          {"update", "refit"},
          {"frames", 2},
          {"average",
           {{"update_ms", update},
            {"trace_ms", total - update},
            {"total_ms", total},
            {"mrays_per_s", {{"primary", rate}, {"ao", rate}, {"shadow", rate}, {"total", rate}}},
            {"rays_per_frame", {{"total", 1000}}}}},
          {"per_frame", {{"total_ms", {total, total}}, {"mrays_per_s", {rate, rate}}}}};
}

json results(const std::string& sceneName, uint32_t triangles, bool withPaper) {
  json scene;
  scene["name"] = sceneName;
  scene["triangles"] = triangles;
  scene["kind"] = "bart";
  scene["table1"] = {{"eval_frames", 3}, {"methods", json::array()}};
  const std::vector<std::tuple<std::string, double, double, double>> rows = {
      {"rebuild", 20.0, 56.2, 56.6}, {"sahstar", 2.5, 56.5, 57.5}, {"sah0", 0.07, 68.79, 70.8},
      {"tsah0", 0.74, 56.52, 56.77}, {"tsah2", 0.76, 56.42, 56.65}, {"tsah4", 0.66, 56.55, 56.82}};
  for (const auto& [id, build, average, maximum] : rows)
    scene["table1"]["methods"].push_back({{"name", id},
                                          {"label", id == "sah0" ? "SAH0" : id},
                                          {"build_s", build},
                                          {"average", average},
                                          {"maximum", maximum},
                                          {"per_frame", {average, maximum, average}}});
  scene["convergence"] = json::array(
      {{{"selection", "mh"}, {"label", "Metropolis-Hastings"}, {"history", {{{"elapsed_s", 0.0}, {"average", 70.0}}, {{"elapsed_s", 0.5}, {"average", 60.0}}}}}});
  scene["runtime"] = {{"device", "cpu"}, {"frames", 2}, {"width", 64}, {"height", 48}, {"camera", "fitted"},
                      {"methods", {runtimeMethod("sah0", "SAH0 refit", 3.0, 4.0, 2000.0),
                                   runtimeMethod("tsah0", "T-SAH k=0 refit", 4.0, 4.5, 1900.0),
                                   runtimeMethod("tsah0-seg3", "T-SAH k=0 refit, 3 trees", 4.2, 4.4, 1950.0)}}};
  scene["segments"] = {{"count", 3},
                       {"build_s", 2.0},
                       {"one_tree", {{"build_s", 0.74}, {"average", 56.52}, {"maximum", 56.77}}},
                       {"k_trees", {{"average", 55.0}, {"maximum", 56.0}, {"per_frame", {55.0, 56.0, 54.0}}}}};
  json toolkit = runtimeMethod("tsah0", "toolkit: T-SAH k=0 refit", 3.9, 4.0, 2000.0);
  json medium = runtimeMethod("embree-medium", "Embree rebuild (medium)", 24.0, 9.0, 950.0);
  json refit = runtimeMethod("embree-refit", "Embree refit", 7.0, 8.0, 900.0);
  medium["extra"] = {{"hits_minus_toolkit", {{"primary", 0}, {"ao_occluded", -1}, {"shadow_occluded", 2}}}};
  scene["embree"] = {{"status", "3.13.5"}, {"frames", 2}, {"methods", {toolkit, medium, refit}}};
  if (withPaper)
    if (const auto* p = tsah::bench::findPaperScene(sceneName, triangles, false)) scene["paper"] = tsah::bench::paperJson(*p);
  json r;
  r["command"] = "tsah bench robot";
  r["machine"] = {{"cpu", "Test CPU"}, {"logical_cores", 2}};
  r["versions"] = {{"tsah", "0.1.0"}, {"compiler", "GCC"}, {"embree", "3.13.5"}};
  r["options"] = {{"frames", 5}, {"eval_frames", 3}, {"trace_frames", 2}, {"device", "cpu"}};
  r["notes"] = {"a note"};
  r["scenes"] = {scene};
  r["paper_source"] = tsah::bench::kPaperSource;
  return r;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(BenchReport, MarkdownHoldsBothTablesWithThePapersFiguresBesideThem) {
  const std::string md = tsah::bench::renderMarkdown(results("robot", 71708, true));
  const char* const expected[] = {
      "# tsah bench: results",
      "    tsah bench robot\n",
      "**Machine:** Test CPU, 2 logical cores",
      "- a note\n",
      "## robot",
      // Table 1 with the paper's columns (BART Robots: SAH0 0.4 s, 69, 71).
      "| method | build [s] | cost | max cost | paper build [s] | paper cost | paper max |",
      "| SAH0 | 0.07 | 68.79 | 70.80 | 0.400 | 69 | 71 |",
      // Table 2 with the paper's (T-SAH Cf0: 7.1 ms, 190.7 MRays/s, 68.2 ms); rows the paper lacks stay empty.
      "| T-SAH k=0 refit | 4.00 | 4.50 | 1900 | 4.50 / 4.50 / 4.50 | 1,000 | 7.1 | 190.7 | 68.2 |",
      "| T-SAH k=0 refit, 3 trees | 4.20 | 4.40 | 1950 | 4.40 / 4.40 / 4.40 | 1,000 | | | |",
      "*paper only:* HLBVH-med (GPU rebuild) | | | | | | 18.1 | 117 | 119.7 |",
      // Segments and Embree.
      "| 3, equal time | 2.00 | 55.00 | 56.00 | 4.20 | 4.40 | 1950 |",
      "| Embree rebuild (medium) | 24.0 | 9.00 | 950 | 9.00 / 9.00 / 9.00 | 0 / -1 / 2 |",
      "Trace speed: Embree rebuild (medium) wins, 2.25× the toolkit's (9.00 vs 4.00 MRays/s).",
      "Update: the toolkit's refit takes 3.90 ms, Embree's refit 7.00 ms (toolkit wins).",
      "Total frame time: Embree refit wins (900 vs 2000 ms, the toolkit 122% slower).",
      "## Toolkit vs Embree: where each wins",
      "Eurographics 2015",
  };
  for (const char* part : expected) EXPECT_TRUE(contains(md, part)) << "missing: " << part << "\n" << md;
}

TEST(BenchReport, NoPaperColumnsForOtherScenesAndContextOnlyForMuseum) {
  const std::string other = tsah::bench::renderMarkdown(results("horse-gallop", 16843, true));
  EXPECT_FALSE(contains(other, "paper cost"));
  EXPECT_FALSE(contains(other, "paper update"));
  const std::string museum = tsah::bench::renderMarkdown(results("museum", 11564, true));
  EXPECT_FALSE(contains(museum, "paper cost")) << "another version of the scene: no side-by-side columns";
  EXPECT_TRUE(contains(museum, "another version of the scene than the data's"));
  EXPECT_TRUE(contains(museum, "with three trees (Museum*) 118.3 MRays/s and 110.8 ms"));
}

TEST(BenchReport, TheToolkitWinsWhereItIsFaster) {
  json r = results("robot", 71708, false);
  json& methods = r["scenes"][0]["embree"]["methods"];
  methods[0] = runtimeMethod("tsah0", "toolkit: T-SAH k=0 refit", 1.0, 20.0, 500.0);
  const std::string md = tsah::bench::renderMarkdown(r);
  EXPECT_TRUE(contains(md, "Trace speed: the toolkit wins, 2.22× the fastest Embree variant, Embree rebuild (medium) (20.0 vs 9.00 MRays/s).")) << md;
  EXPECT_TRUE(contains(md, "Total frame time: the toolkit wins (500 vs 900 ms for Embree refit, 80% slower)."));
}

bool isPng(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  char magic[8] = {};
  in.read(magic, 8);
  return in && std::string(magic + 1, 3) == "PNG";
}

TEST(BenchReport, PlotsWithGnuplotOrASkipThatSaysWhy) {
  const auto dir = tsah::test::scratchDir();
  const json r = results("robot", 71708, false);
  const char* path = std::getenv("PATH");
  const std::string saved = path ? path : "";
  ::setenv("PATH", "", 1);
  const tsah::bench::PlotOutcome none = tsah::bench::makePlots(r, dir);
  ::setenv("PATH", saved.c_str(), 1);
  EXPECT_FALSE(none.made);
  EXPECT_TRUE(none.files.empty());
  EXPECT_EQ(none.status.rfind("skipped: gnuplot is not installed", 0), 0u) << none.status;

  if (!tsah::bench::programInPath("gnuplot")) GTEST_SKIP() << "gnuplot is not installed";
  const tsah::bench::PlotOutcome plots = tsah::bench::makePlots(r, dir);
  EXPECT_TRUE(plots.made) << plots.status;
  EXPECT_EQ(plots.files, (std::vector<std::string>{"plots/robot-cost.png", "plots/robot-convergence.png",
                                                   "plots/robot-total.png", "plots/robot-speed.png",
                                                   "plots/robot-embree.png"}))
      << plots.status;
  for (const std::string& f : plots.files) {
    EXPECT_TRUE(isPng(dir / f)) << f;
    EXPECT_FALSE(std::filesystem::exists(dir / (f + ".tmp"))) << f;
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "plots" / "robot-cost.gp"));
  EXPECT_TRUE(std::filesystem::exists(dir / "plots" / "robot-cost.dat"));
  // A data folder name with a quote still plots (the script quotes paths).
  const auto odd = dir / "it's here";
  const tsah::bench::PlotOutcome quoted = tsah::bench::makePlots(r, odd);
  EXPECT_EQ(quoted.files.size(), 5u) << quoted.status;
}

// `--segments 1` with the default budget records one tree and the budget mode, no K trees: the
// report and the plots must still be made (they read segments.k_trees only where it exists).
TEST(BenchReport, SegmentsWithoutKTreesStillReportAndPlot) {
  json r = results("robot", 71708, false);
  json& segments = r["scenes"][0]["segments"];
  segments.erase("k_trees");
  segments.erase("build_s");
  segments["count"] = 1;
  segments["budget_mode"] = {{"trees", 1},       {"split_times", json::array()}, {"methods", json::array()},
                             {"build_s", 0.7},   {"search_s", 0.1},              {"candidate_trees", 1},
                             {"average", 56.52}, {"maximum", 56.77},             {"per_frame", {56.0, 56.5, 57.0}},
                             {"budget", 1.05},   {"met", true}};
  std::string md;
  EXPECT_NO_THROW(md = tsah::bench::renderMarkdown(r));
  EXPECT_FALSE(contains(md, "one tree vs K trees")) << "no K-tree row without K trees";

  if (!tsah::bench::programInPath("gnuplot")) GTEST_SKIP() << "gnuplot is not installed";
  const auto dir = tsah::test::scratchDir() / "segments-one";
  tsah::bench::PlotOutcome plots;
  EXPECT_NO_THROW(plots = tsah::bench::makePlots(r, dir));
  EXPECT_EQ(plots.files.size(), 5u) << plots.status;
}

}  // namespace
