// tsah optimize INPUT -o OUT.tbvh [--method tsah|sah0|sahstar] [--k K] [--frames N]
//   [--eval-frames M] [--selection mh|random|batch] [--seed S] [--ct 3] [--ci 2] [--max-leaf 8]
//   [--time-limit SEC] [--threads T] [--segments K] [--json]
// Builds one tree for the whole animation, writes it as .tbvh and reports its cost over the
// evaluation frames. With --segments K > 1: K trees, one per equal-time part of the animation
// (the paper's BART Museum*), written as OUT_seg0.tbvh ... OUT_seg<K-1>.tbvh; each file's time
// range is its part, and a frame is meant to be traced with the tree whose range holds it.
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>

#include "bench/segments.hpp"
#include "animation_frames.hpp"
#include "cli.hpp"
#include "tsah/baselines.hpp"
#include "tsah/bvh_file.hpp"
#include "tsah/pipeline.hpp"

namespace {

struct Options {
  tsah::TreeOptions tree;  // method, k, frames, selection, seed, ct, ci, maxLeaf, limits, threads
  std::string input, output;
  uint32_t evalFrames = 50;
  uint32_t segments = 1;
  bool json = false;
};



nlohmann::json optimizationJson(const tsah::InsertionOptimizer::Result& details) {
  nlohmann::json history = nlohmann::json::array();
  for (const auto& r : details.history)
    history.push_back({{"batch", r.batch}, {"cost", r.cost}, {"average", r.averageCost},
                       {"elapsed_s", r.elapsedSeconds}, {"steps", r.steps}});
  return {{"initial_cost", details.initialCost},
          {"final_cost", details.finalCost},
          {"batches", details.history.empty() ? 0 : details.history.size() - 1},
          {"steps", details.steps},
          {"accepted_steps", details.acceptedSteps},
          {"seconds", details.seconds},
          {"time_limit_reached", details.timeLimitReached},
          {"history", history}};
}

std::pair<double, double> averageAndMaximum(const std::vector<double>& costs) {
  double average = 0.0, maximum = 0.0;
  for (double c : costs) {
    average += c / double(costs.size());
    maximum = std::max(maximum, c);
  }
  return {average, maximum};
}

// --segments K: K trees for K equal-time parts; all are built before any file is written, so a
// failure leaves no partial set behind.
void runSegments(const Options& opt, const tsah::TreeOptions& treeOpt, const anim::Animation& a, uint32_t frames,
                 uint32_t evalFrames, const tsah::BaselineConfig& config, tsah::cli::Progress& progress) {
  const tsah::MethodSpec method = treeOpt.methodSpec();
  progress.message("building " + std::to_string(opt.segments) + " trees");
  const std::vector<tsah::bench::SegmentTree> trees =
      tsah::bench::buildSegmentTrees(a, opt.segments, frames, method, config);
  progress.message("evaluating " + std::to_string(evalFrames) + " frames");
  const std::vector<double> times = a.uniformTimes(evalFrames);
  const std::vector<double> perFrame = tsah::bench::evaluateSegmentTrees(a, trees, times, config.cost, opt.tree.threads);
  std::vector<tsah::bench::TimeSegment> parts;
  for (const auto& t : trees) parts.push_back(t.segment);
  std::vector<std::vector<double>> partCosts(trees.size());
  for (std::size_t i = 0; i < times.size(); ++i) partCosts[tsah::bench::segmentOf(parts, times[i])].push_back(perFrame[i]);

  nlohmann::json segments = nlohmann::json::array();
  for (uint32_t s = 0; s < trees.size(); ++s) {
    const tsah::bench::SegmentTree& t = trees[s];
    const std::string path = tsah::bench::segmentPath(opt.output, s);
    tsah::saveBvhFile(path, t.bvh, tsah::treeBuildInfo(treeOpt, a, frames, t.buildSeconds, t.segment.start, t.segment.end));
    const auto [average, maximum] = averageAndMaximum(partCosts[s]);
    nlohmann::json j = {{"index", s},
                        {"output", path},
                        {"time_start", t.segment.start},
                        {"time_end", t.segment.end},
                        {"nodes", t.bvh.nodeCount()},
                        {"leaves", t.bvh.leafCount()},
                        {"depth", t.bvh.depth()},
                        {"build_s", t.buildSeconds},
                        {"eval_frames", partCosts[s].size()},
                        {"cost", {{"average", average}, {"maximum", maximum}}}};
    if (method.method == tsah::Method::TSah) j["optimization"] = optimizationJson(t.optimization);
    segments.push_back(j);
  }
  const auto [average, maximum] = averageAndMaximum(perFrame);
  progress.message("done");
  if (opt.json) {
    nlohmann::json j;
    j["input"] = opt.input;
    j["output"] = opt.output;
    j["method"] = method.method == tsah::Method::TSah ? "tsah" : method.name();
    j["k"] = method.k;
    j["selection"] = method.method == tsah::Method::Sah0 ? "none" : opt.tree.selection;
    j["seed"] = opt.tree.seed;
    j["frames"] = frames;
    j["eval_frames"] = evalFrames;
    j["triangles"] = a.triangleCount();
    j["max_leaf"] = opt.tree.maxLeaf;
    j["cost"] = {{"average", average}, {"maximum", maximum}, {"per_frame", perFrame}};
    j["segments"] = segments;
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("%s: %u trees for %u equal-time parts, %s, %u triangles\n", opt.output.c_str(), opt.segments,
              opt.segments, method.name().c_str(), a.triangleCount());
  for (const nlohmann::json& s : segments)
    std::printf("  %s: t %.4g .. %.4g, %u nodes, build %.2f s, cost over %zu evaluation frames: average %.3f, maximum %.3f\n",
                s["output"].get<std::string>().c_str(), s["time_start"].get<double>(), s["time_end"].get<double>(),
                s["nodes"].get<uint32_t>(), s["build_s"].get<double>(), s["eval_frames"].get<std::size_t>(),
                s["cost"]["average"].get<double>(), s["cost"]["maximum"].get<double>());
  std::printf("cost over %u evaluation frames, each with the tree of its part: average %.3f, maximum %.3f\n", evalFrames,
              average, maximum);
}

void run(const Options& opt) {
  tsah::TreeOptions treeOpt = opt.tree;
  const tsah::MethodSpec method = treeOpt.methodSpec();
  const anim::Animation a = tsah::cli::loadInput(opt.input);
  if (a.triangleCount() == 0) throw tsah::cli::UsageError(opt.input + ": no triangles to build a tree over");
  // A static input has one frame: resampling it would only repeat that frame.
  const uint32_t frames = tsah::framesFor(a, opt.tree.frames);
  const uint32_t evalFrames = tsah::framesFor(a, opt.evalFrames);

  tsah::cli::Progress progress("optimize " + method.name());
  treeOpt.progress = [&](const std::string& message) { progress.message(message); };

  if (opt.segments > 1) {
    if (a.keyframeCount() <= 1)
      throw tsah::cli::UsageError(opt.input + ": --segments needs an animation (this input has one frame)");
    return runSegments(opt, treeOpt, a, frames, evalFrames, treeOpt.baselineConfig(), progress);
  }

  const tsah::OptimizedTree tree = tsah::optimizeAnimation(a, treeOpt);
  const tsah::Bvh& bvh = tree.bvh;
  const tsah::InsertionOptimizer::Result& details = tree.optimization;
  const tsah::BvhBuildInfo& info = tree.info;
  const double buildSeconds = info.buildSeconds;

  progress.message("evaluating " + std::to_string(evalFrames) + " frames");
  const std::vector<double> perFrame = tsah::evaluateAnimation(bvh, a, evalFrames, {opt.tree.ct, opt.tree.ci}, opt.tree.threads);
  const auto [average, maximum] = averageAndMaximum(perFrame);
  tsah::saveBvhFile(opt.output, bvh, info);

  nlohmann::json j;
  j["input"] = opt.input;
  j["output"] = opt.output;
  j["method"] = info.method;
  j["k"] = info.k;
  j["selection"] = info.selection;
  j["seed"] = opt.tree.seed;
  j["frames"] = frames;
  j["eval_frames"] = evalFrames;
  j["triangles"] = a.triangleCount();
  j["nodes"] = bvh.nodeCount();
  j["leaves"] = bvh.leafCount();
  j["depth"] = bvh.depth();
  j["max_leaf"] = opt.tree.maxLeaf;
  j["build_s"] = buildSeconds;
  j["cost"] = {{"average", average}, {"maximum", maximum}, {"per_frame", perFrame}};
  if (method.method == tsah::Method::TSah) {
    j["optimization"] = optimizationJson(details);
  }
  progress.message("done");
  if (opt.json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("%s: %s tree, %u triangles, %u nodes, %u leaves, depth %u\n", opt.output.c_str(),
              method.name().c_str(), a.triangleCount(), bvh.nodeCount(), bvh.leafCount(), bvh.depth());
  if (method.method == tsah::Method::TSah)
    std::printf("optimization: T-SAH cost %.3f -> %.3f over %u frames in %zu batches (%.2f s)\n",
                details.initialCost, details.finalCost, frames,
                details.history.empty() ? std::size_t(0) : details.history.size() - 1, details.seconds);
  std::printf("build %.2f s; cost over %u evaluation frames: average %.3f, maximum %.3f\n", buildSeconds,
              evalFrames, average, maximum);
}

}  // namespace

TSAH_REGISTER_COMMAND(40, [](CLI::App& app) {
  auto* sub = app.add_subcommand("optimize", "Build one BVH for the whole animation (T-SAH, SAH0 or SAH*) as .tbvh");
  auto opt = std::make_shared<Options>();
  sub->add_option("INPUT", opt->input, "Animation or static mesh (any input `tsah info` reads)")->required();
  sub->add_option("-o,--output", opt->output, "Output .tbvh file")->required();
  sub->add_option("--method", opt->tree.method, "tsah (one tree optimized for all frames), sah0 (frame 0, refit) or sahstar (best over time)")
      ->check(CLI::IsMember({"tsah", "sah0", "sahstar"}))
      ->capture_default_str();
  sub->add_option("--k", opt->tree.k, "T-SAH exponent: 0 optimizes the average cost, larger values the worst frames")
      ->check(CLI::Range(0, 16))
      ->capture_default_str();
  sub->add_option("--frames", opt->tree.frames, "Representative frames, uniform in time")
      ->check(CLI::Range(1u, 1000u))
      ->capture_default_str();
  sub->add_option("--eval-frames", opt->evalFrames, "Evaluation frames for the reported cost, uniform in time")
      ->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
  sub->add_option("--selection", opt->tree.selection, "Node selection: mh (Metropolis-Hastings), random, batch (batch sorting)")
      ->check(CLI::IsMember({"mh", "random", "batch"}))
      ->capture_default_str();
  sub->add_option("--seed", opt->tree.seed, "Random seed (same seed, same tree)")->capture_default_str();
  sub->add_option("--ct", opt->tree.ct, "Cost of traversing a node")->check(CLI::PositiveNumber)->capture_default_str();
  sub->add_option("--ci", opt->tree.ci, "Cost of intersecting a triangle")->check(CLI::PositiveNumber)->capture_default_str();
  sub->add_option("--max-leaf", opt->tree.maxLeaf, "Largest leaf after collapse (1: one triangle per leaf)")
      ->check(CLI::Range(1u, 256u))
      ->capture_default_str();
  sub->add_option("--time-limit", opt->tree.timeLimit, "Stop each optimization after this many seconds (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub->add_option("--min-improvement", opt->tree.minImprovement,
                  "Stop after 3 batches that lower the cost by less than this fraction each (0: by nothing)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  sub->add_option("--threads", opt->tree.threads, "Worker threads (0: all cores)")->capture_default_str();
  sub->add_option("--segments", opt->segments,
                  "K > 1: one tree per equal-time part of the animation, written as OUT_seg0 ... OUT_seg<K-1>")
      ->check(CLI::Range(1u, 1000u))
      ->capture_default_str();
  sub->add_flag("--json", opt->json, "Print one JSON object");
  sub->callback([opt] { run(*opt); });
});
