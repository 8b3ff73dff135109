// tsah optimize INPUT -o OUT.tbvh [--method tsah|sah0|sahstar] [--k K] [--frames N]
//   [--eval-frames M] [--selection mh|random|batch] [--seed S] [--ct 3] [--ci 2] [--max-leaf 8]
//   [--time-limit SEC] [--threads T] [--segments K|auto] [--budget X | --budget-cost C]
//   [--overlap S] [--reference-frames N] [--max-trees N] [--structure flat|two-level|auto]
//   [--tlas-trees K|auto] [--tlas-budget X] [--json]
// Builds one tree for the whole animation, writes it as .tbvh and reports its cost over the
// evaluation frames. With --segments K > 1 (count mode) or --segments auto (budget mode), a tree
// set instead (docs/segmentation.md): K trees, or the fewest trees that keep every evaluation frame
// within the budget, with split points chosen by tsah::segmentTimeline, written as one .tbvh set
// file (version 2) that `tsah trace`, `export`, `info` and `bench` switch through by themselves.
// A scene file may instead be kept as two levels (--structure two-level, or auto's choice: one tree
// per source and a top-level tree over the instances, docs/two-level.md), written as a version 3 file.
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>

#include "animation_frames.hpp"
#include "cli.hpp"
#include "optimizer_options.hpp"
#include "scale_out.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/optimize/segmentation.hpp"
#include "tsah/io/tree_set.hpp"
#include "two_level_cli.hpp"
#if TSAH_HAVE_CUDA
#include "tsah_cuda/device.hpp"
#endif

namespace {

struct Options {
  tsah::TreeOptions tree;  // method, k, frames, selection, seed, ct, ci, maxLeaf, limits, threads
  std::string input, output;
  uint32_t evalFrames = 50;
  std::string segments = "1";  // K or "auto"
  double budget = 0.0;         // relative budget (factor of the per-frame optimized cost)
  double budgetCost = 0.0;     // absolute budget
  double overlap = 0.0;
  uint32_t referenceFrames = tsah::SegmentationConfig{}.referenceFrames;
  uint32_t maxTrees = tsah::SegmentationConfig{}.maxTrees;
  bool json = false;
  bool reproducible = false;  // build times written as 0
  std::string devices;        // --devices all|0,2,...
  std::string structure;      // flat, two-level, auto; empty: auto for scene files, flat otherwise
  std::string tlasTrees = "auto";  // two levels: K top-level trees or auto (tsah::TlasOptions)
  double tlasBudget = tsah::TlasOptions{}.budget;
  bool tlasGiven = false;          // --tlas-trees or --tlas-budget on the command line
  tsah::TlasOptions tlas;          // the two, parsed before anything is loaded
};

tsah::TlasOptions tlasOptions(const Options& opt) {
  tsah::TlasOptions tlas;
  tlas.budget = opt.tlasBudget;
  if (opt.tlasTrees == "auto") return tlas;
  const std::string& k = opt.tlasTrees;
  const bool number = !k.empty() && k.size() < 5 && k.find_first_not_of("0123456789") == std::string::npos;
  if (!number || std::stoul(k) < 1 || std::stoul(k) > tsah::TlasOptions::kMaxTrees)
    throw tsah::cli::UsageError("--tlas-trees expects a number of trees (1.." +
                                std::to_string(tsah::TlasOptions::kMaxTrees) + ") or auto, got '" + k + "'");
  tlas.trees = uint32_t(std::stoul(k));
  return tlas;
}



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

// --segments K|auto: a tree set (tsah::optimizeTreeSet), written as one file after every tree is built.
void runSegments(const Options& opt, const tsah::TreeOptions& treeOpt, const anim::Animation& a, uint32_t frames,
                 uint32_t evalFrames, tsah::cli::Progress& progress) {
  const tsah::MethodSpec method = treeOpt.methodSpec();
  tsah::TreeSetOptions so;
  so.tree = treeOpt;
  so.evalFrames = evalFrames;
  so.segments = opt.segments == "auto" ? 0u : static_cast<uint32_t>(std::stoul(opt.segments));
  so.budget = opt.budget;
  so.budgetCost = opt.budgetCost;
  so.overlap = opt.overlap;
  so.referenceFrames = opt.referenceFrames;
  so.maxTrees = opt.maxTrees;
  so.reproducible = opt.reproducible;
  // The candidate trees dealt to the GPUs of --devices (each worker thread on its own GPU; the GPU
  // optimizer uses the thread's), to this rank's GPU, or built here on the CPU; and to the ranks.
  std::vector<int> gpus;
  if (opt.tree.device == tsah::Device::Cuda)
    gpus = opt.devices.empty() ? std::vector<int>{tsah::cli::rankDevice()} : tsah::cli::parseDevices(opt.devices);
  const auto dealer = tsah::cli::makeDealer(unsigned(std::max<std::size_t>(1, gpus.size())), [&gpus](unsigned w) {
#if TSAH_HAVE_CUDA
    if (!gpus.empty()) tsah::cuda::useDevice(gpus[w]);
#endif
  });
  so.dealer = dealer.get();
  const tsah::OptimizedTreeSet set = tsah::optimizeTreeSet(a, so);
  if (!tsah::cli::job::leader()) return;  // every rank has the result; one writes it
  const tsah::SegmentationResult& r = set.search;
  const tsah::TreeSetInfo& setInfo = set.info;
  const bool budgetMode = so.segments == 0;

  nlohmann::json parts = nlohmann::json::array();
  for (uint32_t s = 0; s < set.trees.size(); ++s) {
    const tsah::BvhBuildInfo& info = set.builds[s];
    std::vector<double> mine;
    for (std::size_t f = 0; f < r.times.size(); ++f)
      if (tsah::treeIndexAt(r.parts, r.times[f]) == s) mine.push_back(r.costs[f]);
    const auto [average, maximum] = averageAndMaximum(mine);
    nlohmann::json j = {{"index", s},
                        {"time_start", r.parts[s].start},
                        {"time_end", r.parts[s].end},
                        {"build_range", {r.buildRanges[s].start, r.buildRanges[s].end}},
                        {"method", info.method},
                        {"nodes", set.trees[s].nodeCount()},
                        {"depth", set.trees[s].depth()},
                        {"build_s", r.buildSeconds[s]},
                        {"eval_frames", mine.size()},
                        {"cost", {{"average", average}, {"maximum", maximum}}}};
    if (r.methods[s] != "sah-frame" && method.method == tsah::Method::TSah)
      j["optimization"] = optimizationJson(r.optimizations[s]);
    parts.push_back(j);
  }
  set.save(opt.output);
  progress.message("done");

  nlohmann::json j;
  j["input"] = opt.input;
  j["output"] = opt.output;
  j["segmentation"] = setInfo.segmentation;
  j["method"] = method.method == tsah::Method::TSah ? "tsah" : method.name();
  j["k"] = method.k;
  j["seed"] = opt.tree.seed;
  j["frames"] = frames;
  j["eval_frames"] = evalFrames;
  j["triangles"] = a.triangleCount();
  j["trees"] = set.trees.size();
  j["overlap"] = opt.overlap;
  j["candidate_trees_built"] = r.treesBuilt;
  j["workers"] = {{"ranks", tsah::cli::job::size()}, {"per_rank", dealer->localWorkers()}};
  j["search_s"] = r.searchSeconds;
  j["cost"] = {{"average", r.average}, {"maximum", r.maximum}, {"per_frame", r.costs}};
  if (budgetMode) {
    j["budget"] = {{"value", setInfo.budget},
                   {"relative", setInfo.budgetRelative},
                   {"met", r.budgetMet},
                   {"bound_per_frame", r.bound},
                   {"reference_s", r.referenceSeconds}};
    if (setInfo.budgetRelative) {
      double peakRatio = 0.0, ratioSum = 0.0, refSum = 0.0;
      for (std::size_t f = 0; f < r.costs.size(); ++f) {
        peakRatio = std::max(peakRatio, r.costs[f] / r.reference[f]);
        ratioSum += r.costs[f];
        refSum += r.reference[f];
      }
      j["budget"]["reference_per_frame"] = r.reference;
      j["budget"]["peak_ratio"] = peakRatio;
      j["budget"]["average_ratio"] = ratioSum / refSum;
    }
  }
  j["parts"] = parts;
  if (opt.json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("%s: a set of %zu trees (%s segmentation, %s), %u triangles; %u candidate trees built in %.2f s\n",
              opt.output.c_str(), set.trees.size(), setInfo.segmentation.c_str(), method.name().c_str(),
              a.triangleCount(), r.treesBuilt, r.searchSeconds);
  for (const nlohmann::json& p : parts)
    std::printf("  tree %u: t %.4g .. %.4g (%s), %u nodes, build %.2f s, cost over %zu evaluation frames: average %.3f, maximum %.3f\n",
                p["index"].get<uint32_t>(), p["time_start"].get<double>(), p["time_end"].get<double>(),
                p["method"].get<std::string>().c_str(), p["nodes"].get<uint32_t>(), p["build_s"].get<double>(),
                p["eval_frames"].get<std::size_t>(), p["cost"]["average"].get<double>(),
                p["cost"]["maximum"].get<double>());
  std::printf("cost over %u evaluation frames, each with the tree of its part: average %.3f, maximum %.3f\n", evalFrames,
              r.average, r.maximum);
  if (j.contains("budget")) {
    if (setInfo.budgetRelative)
      std::printf("budget %.3gx the per-frame optimized cost: %s; peak ratio %.4f, average ratio %.4f\n", setInfo.budget,
                  r.budgetMet ? "met on every evaluation frame" : "MISSED on some evaluation frames",
                  j["budget"]["peak_ratio"].get<double>(), j["budget"]["average_ratio"].get<double>());
    else
      std::printf("budget: cost <= %.4g: %s\n", setInfo.budget,
                  r.budgetMet ? "met on every evaluation frame" : "MISSED on some evaluation frames");
  }
}

// --structure: true when the scene is to be kept as two levels (then written here). Two-level is
// refused for inputs that are not scene files and with the options only a flat tree reads; auto
// (the default for scene files) applies tsah::cli::chooseStructure unless such options ask for a
// flat tree; when it flattens every object, flatChoice receives its decision and the flat tree is built.
bool runTwoLevel(const Options& opt, nlohmann::json& flatChoice) {
  using tsah::cli::UsageError;
  const bool scene = anim::isSceneFile(opt.input);
  const std::string structure = opt.structure.empty() ? (scene ? "auto" : "flat") : opt.structure;
  if (opt.tlasGiven && !scene)
    throw UsageError("--tlas-trees and --tlas-budget shape the top level of two levels: " + opt.input +
                     " is one animation, not a scene file");
  if (structure == "flat") return false;
  const bool asked = structure == "two-level";
  if (asked && !scene)
    throw UsageError("--structure two-level needs a scene file (.json with objects); " + opt.input +
                     " is one animation: use --structure flat");
  const bool flatOnly = opt.segments != "1" || !opt.devices.empty() || opt.tree.method != tsah::Method::TSah;
  if (asked && flatOnly)
    throw UsageError("--structure two-level builds one T-SAH tree per source and the top level: it does not go "
                     "with --segments, --devices or --method other than tsah");
  if (opt.tlasGiven && flatOnly)
    throw UsageError("--tlas-trees and --tlas-budget shape the top level of two levels: not with --segments, --devices "
                     "or --method other than tsah");
  if (!scene || flatOnly) return false;
  const auto loadStart = std::chrono::steady_clock::now();
  anim::SceneSources sources = tsah::cli::loadSceneSourcesForCli(opt.input);
  const double loadSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - loadStart).count();
  if (asked) {
    if (tsah::cli::job::leader())
      tsah::cli::optimizeTwoLevel(std::move(sources), opt.input, opt.output, opt.tree, opt.tlas, nullptr, opt.json,
                                  loadSeconds, opt.reproducible);
    return true;
  }
  const tsah::StructureChoice choice = tsah::cli::chooseStructure(sources, opt.tree);
  if (choice.allFlattened()) {
    flatChoice = tsah::cli::describeStructureChoice(choice);
    return false;
  }
  if (tsah::cli::job::leader())
    tsah::cli::optimizeTwoLevel(std::move(sources), opt.input, opt.output, opt.tree, opt.tlas, &choice, opt.json,
                                loadSeconds, opt.reproducible);
  return true;
}

void run(const Options& opt) {
  // --threads holds every phase to that many threads: loading, builders, optimizers, writing.
  std::optional<tbb::global_control> threadLimit;
  if (opt.tree.threads > 0) threadLimit.emplace(tbb::global_control::max_allowed_parallelism, opt.tree.threads);
  tsah::TreeOptions treeOpt = opt.tree;
  const tsah::MethodSpec method = treeOpt.methodSpec();
  tsah::cli::checkTreeDevice(treeOpt);
  if (!opt.devices.empty() && treeOpt.device != tsah::Device::Cuda)
    throw tsah::cli::UsageError("--devices chooses GPUs: use it with --device cuda");
  nlohmann::json structureChoice;  // auto's decision when it chose a flat tree
  if (runTwoLevel(opt, structureChoice)) return;
  const anim::Animation a = tsah::cli::loadInput(opt.input);
  if (a.triangleCount() == 0) throw tsah::cli::UsageError(opt.input + ": no triangles to build a tree over");
  // A static input has one frame: resampling it would only repeat that frame.
  const uint32_t frames = tsah::framesFor(a, opt.tree.frames);
  const uint32_t evalFrames = tsah::framesFor(a, opt.evalFrames);

  tsah::cli::Progress progress("optimize " + method.name());
  treeOpt.progress = [&](const std::string& message) { progress.message(message); };

  const bool budget = opt.budget > 0.0 || opt.budgetCost > 0.0;
  if (opt.segments != "auto") {
    const bool number = !opt.segments.empty() && opt.segments.size() < 5 &&
                        opt.segments.find_first_not_of("0123456789") == std::string::npos;
    if (!number || std::stoul(opt.segments) < 1 || std::stoul(opt.segments) > 1000)
      throw tsah::cli::UsageError("--segments expects a number of trees (1..1000) or auto, got '" + opt.segments + "'");
    if (budget) throw tsah::cli::UsageError("--budget and --budget-cost go with --segments auto");
  }
  if (opt.budget > 0.0 && opt.budgetCost > 0.0) throw tsah::cli::UsageError("give either --budget or --budget-cost");
  if (opt.segments != "1") {
    if (a.keyframeCount() <= 1)
      throw tsah::cli::UsageError(opt.input + ": --segments needs an animation (this input has one frame)");
    if (evalFrames < 2) throw tsah::cli::UsageError("--segments needs at least 2 --eval-frames");
    return runSegments(opt, treeOpt, a, frames, evalFrames, progress);
  }
  if (!opt.devices.empty()) throw tsah::cli::UsageError("--devices deals the candidate trees of --segments");
  // One tree is one unit of work: the other ranks of a job have nothing to do.
  if (!tsah::cli::job::leader()) return;

  const tsah::OptimizedTree tree = tsah::optimizeAnimation(a, treeOpt);
  const tsah::Bvh& bvh = tree.bvh;
  const tsah::InsertionOptimizer::Result& details = tree.optimization;
  const double buildSeconds = tree.info.buildSeconds;
  tsah::BvhBuildInfo info = tree.info;
  if (opt.reproducible) info.buildSeconds = 0.0;

  progress.message("evaluating " + std::to_string(evalFrames) + " frames");
  const std::vector<double> perFrame = tsah::evaluateAnimation(bvh, a, evalFrames, opt.tree.objective.cost, opt.tree.threads);
  const auto [average, maximum] = averageAndMaximum(perFrame);
  tsah::saveBvhFile(opt.output, bvh, info);

  nlohmann::json j;
  j["input"] = opt.input;
  j["output"] = opt.output;
  j["method"] = info.method;
  j["k"] = info.objective.k;
  j["optimizer"] = tsah::name(opt.tree.optimizer);
  j["device"] = tsah::name(opt.tree.device);
  j["selection"] = info.selection;
  j["seed"] = opt.tree.seed;
  j["frames"] = frames;
  j["eval_frames"] = evalFrames;
  j["triangles"] = a.triangleCount();
  j["nodes"] = bvh.nodeCount();
  j["leaves"] = bvh.leafCount();
  j["depth"] = bvh.depth();
  j["max_leaf"] = opt.tree.objective.maxLeafSize;
  j["build_s"] = buildSeconds;
  j["cost"] = {{"average", average}, {"maximum", maximum}, {"per_frame", perFrame}};
  if (method.method == tsah::Method::TSah) {
    j["optimization"] = optimizationJson(details);
  }
  j["peak_rss_bytes"] = tsah::cli::peakResidentBytes();
  if (!structureChoice.is_null()) j["structure_choice"] = structureChoice;
  progress.message("done");
  if (opt.json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  if (!structureChoice.is_null()) tsah::cli::printStructureChoice(structureChoice);
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
  tsah::cli::addChoice(*sub, "--method", opt->tree.method,
                       "tsah (one tree optimized for all frames), sah0 (frame 0, refit) or sahstar (best over time)",
                       {tsah::Method::TSah, tsah::Method::Sah0, tsah::Method::SahStar});
  sub->add_option("--k", opt->tree.objective.k, "T-SAH exponent: 0 optimizes the average cost, larger values the worst frames")
      ->check(CLI::Range(0, 16))
      ->capture_default_str();
  tsah::cli::addTreeOptions(*sub, opt->tree, opt->evalFrames);
  sub->add_option("--segments", opt->segments,
                  "K > 1: a set of K trees with split points minimizing the average cost (the peak with --k > 0); "
                  "auto: the fewest trees within --budget; written as one .tbvh tree set")
      ->capture_default_str();
  sub->add_option("--budget", opt->budget,
                  "--segments auto: every evaluation frame's cost within this factor of a per-frame optimized SAH "
                  "tree (default 1.05)")
      ->check(CLI::Range(1.0, 100.0));
  sub->add_option("--budget-cost", opt->budgetCost, "--segments auto: an absolute bound on every evaluation frame's cost")
      ->check(CLI::PositiveNumber);
  auto* overlap = sub->add_option("--overlap", opt->overlap,
                  "Seconds of overlap between consecutive trees (each built for its part widened by half of it; "
                  "the runtimes switch in its middle)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  auto* referenceFrames = sub->add_option("--reference-frames", opt->referenceFrames,
                  "--budget: per-frame optimized SAH trees on this many evaluation frames, linear in between "
                  "(0: every evaluation frame)")
      ->capture_default_str();
  auto* maxTrees = sub->add_option("--max-trees", opt->maxTrees, "--segments auto: at most this many trees")
      ->check(CLI::Range(1u, tsah::kTbvhMaxTrees))
      ->capture_default_str();
  sub->add_option("--structure", opt->structure,
                  "flat: one tree over the baked scene; two-level: one tree per source and a top-level tree over "
                  "the instances (scene files, .tbvh version 3); auto (the default for scene files): per object, "
                  "flattened into the parent level when that makes its estimated cost 10% lower (or it is one "
                  "instance without a path), else kept as instances; every object flattened: flat")
      ->check(CLI::IsMember({"flat", "two-level", "auto"}));
  auto* tlasTrees = sub->add_option("--tlas-trees", opt->tlasTrees,
                  "Two levels: this many top-level trees, each optimized over its part of the scene's time (equal "
                  "frame counts, then the boundaries moved where that lowers the average cost), or auto: the fewest "
                  "of 1, 2, 4 ... 32 whose average cost is within --tlas-budget of a TLAS rebuilt at every frame")
      ->capture_default_str();
  auto* tlasBudget = sub->add_option("--tlas-budget", opt->tlasBudget,
                  "--tlas-trees auto: the factor of the per-frame rebuilt TLAS's average cost to reach")
      ->check(CLI::Range(1.0, 100.0))
      ->capture_default_str();
  sub->add_flag("--json", opt->json, "Print one JSON object");
  sub->add_flag("--reproducible", opt->reproducible,
                "Write 0 as every tree's build time: the same inputs give the same file bytes, however the work "
                "was split (--devices, MPI ranks)");
  sub->add_option("--devices", opt->devices,
                  "--segments with --device cuda: all, or GPU indices such as 0,2: candidate trees optimized on "
                  "these GPUs at once");
  // Options that only a tree set (or only the budget search) reads are refused elsewhere, not ignored.
  sub->callback([opt, overlap, referenceFrames, maxTrees, tlasTrees, tlasBudget] {
    using tsah::cli::UsageError;
    if ((tlasTrees->count() || tlasBudget->count()) && opt->structure == "flat")
      throw UsageError("--tlas-trees and --tlas-budget shape the top level of two levels: not with --structure flat");
    if (tlasBudget->count() && opt->tlasTrees != "auto") throw UsageError("--tlas-budget goes with --tlas-trees auto");
    opt->tlasGiven = tlasTrees->count() || tlasBudget->count();
    opt->tlas = tlasOptions(*opt);
    if (overlap->count() && opt->segments == "1") throw UsageError("--overlap goes with --segments (a tree set)");
    if (maxTrees->count() && opt->segments != "auto") throw UsageError("--max-trees goes with --segments auto");
    if (referenceFrames->count() && (opt->segments != "auto" || opt->budgetCost > 0.0))
      throw UsageError("--reference-frames goes with --segments auto and a relative --budget");
    run(*opt);
  });
});
