// The two-level part of the bench (two_level_bench.hpp): flat tree, two-level structure and Embree
// instancing of one scene file on the same rays.
#include "bench/two_level_bench.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>

#include "anim/scene.hpp"
#include "bench/embree_instanced.hpp"
#include "bench/embree_peer.hpp"
#include "bench/motion_bench.hpp"
#include "bench/process.hpp"
#include "bench/runtime_bench.hpp"
#include "tsah/base/error.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/scene/two_level_runtime.hpp"

namespace tsah::bench {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// A number as an argument that reads back as the same double.
std::string exactText(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

// One `tsah optimize SCENE --structure STRUCTURE --json` child: wall time, its build time, peak
// resident memory (the child's VmHWM when it reports one; else its ru_maxrss, which also counts
// this process: a posix_spawn child shares its parent's memory until exec).
json optimizeChild(const SceneSource& scene, const std::string& structure, const fs::path& tree, const BenchOptions& o) {
  const bool gpu = o.optimizer == "cuda";
  std::vector<std::string> argv = {o.program, "optimize", scene.input, "-o", tree.string(), "--structure", structure,
                                   "--optimizer", gpu ? "parallel" : o.optimizer, "--device", gpu ? "cuda" : "cpu",
                                   "--threads", std::to_string(o.threads), "--frames", std::to_string(o.frames),
                                   "--seed", std::to_string(o.seed), "--max-leaf",
                                   std::to_string(o.objective.maxLeafSize), "--ct", exactText(o.objective.cost.ct),
                                   "--ci", exactText(o.objective.cost.ci), "--json"};
  // The import options of the run, so that the trees are built for the scene this process bakes.
  if (o.fps > 0.0) argv.insert(argv.end(), {"--fps", exactText(o.fps)});
  if (!o.clip.empty()) argv.insert(argv.end(), {"--clip", o.clip});
  const fs::path report = fs::path(tree).replace_extension(".json");
  const auto start = std::chrono::steady_clock::now();
  const ProcessResult r = runProcess(argv, report.string());
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!r.ok())
    throw tsah::Failure(scene.input + ": tsah optimize --structure " + structure + " failed" +
                        (r.output.empty() ? "" : ": " + r.output.substr(0, r.output.find('\n'))));
  std::ifstream in(report);
  const json j = json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.contains("build_s"))
    throw tsah::Failure(scene.input + ": unreadable tsah optimize --structure " + structure + " report");
  const bool ownPeak = j.value("peak_rss_bytes", 0.0) > 0.0;
  return {{"tree", tree.string()},
          {"structure", j.value("structure", std::string("flat"))},
          {"wall_s", wall},
          {"build_s", j["build_s"]},
          {"cpu_s", r.cpuSeconds},
          {"peak_rss_bytes", ownPeak ? j["peak_rss_bytes"].get<double>() : double(r.maxRssKb) * 1024.0},
          {"peak_source", ownPeak ? "VmHWM of tsah optimize" : "ru_maxrss of the tsah optimize child, the bench process included"}};
}

// traceFrames scene frames spread evenly over the scene's frames (all of them when fewer).
std::vector<double> tracedFrames(const std::vector<double>& frames, uint32_t traceFrames) {
  const std::size_t n = frames.size(), count = std::min<std::size_t>(traceFrames, n);
  if (count <= 1) return {frames.front()};
  std::vector<double> times;
  for (std::size_t i = 0; i < count; ++i) times.push_back(frames[(i * (n - 1) + (count - 1) / 2) / (count - 1)]);
  return times;
}

// The two-level runtime as a batch tracer; hits as baked triangle ids (SceneSources::bakedTriangle:
// flattened objects' triangles map back to their own instances).
BatchTracer twoLevelTracer(const TwoLevelRuntime& rt) {
  BatchTracer tracer;
  const anim::SceneSources* sources = &rt.scene().scene;
  tracer.closest = [&rt, sources](const Ray* rays, const float*, std::size_t count, Hit* hits) {
    for (std::size_t i = 0; i < count; ++i) {
      const TwoLevelHit h = rt.closestHit(rays[i]);
      hits[i] = h.valid() ? Hit{h.t, h.u, h.v, sources->bakedTriangle(h.instance, h.prim)} : Hit{};
    }
  };
  tracer.occluded = [&rt](const Ray* rays, const float*, std::size_t count, AnyHitOrder order, uint8_t* occluded) {
    for (std::size_t i = 0; i < count; ++i) occluded[i] = rt.anyHit(rays[i], order) ? 1 : 0;
  };
  return tracer;
}

double ratio(double a, double b) { return a / std::max(b, 1e-12); }

// The GPU figures: tsah_two_level_gpu_bench (GpuTwoLevelRuntime against GpuRuntime over the flat
// tree) on the two trees just optimized, with BLAS and flat tree in `layout`; its JSON as it is.
// The binary layout's run also compares the TLAS updates and times the host TLAS rebuild (the
// reference); the compressed layout's has the same binary TLAS, so it refits it only.
json gpuFigures(const SceneSource& scene, const json& optimize, std::size_t frames, const BenchOptions& o,
                const std::string& layout) {
  const fs::path report =
      fs::path(optimize["two_level"]["tree"].get<std::string>()).replace_extension("." + layout + ".gpu.json");
  std::vector<std::string> argv = {o.gpuTwoLevelProgram, scene.input, "--tree",
                                   optimize["two_level"]["tree"].get<std::string>(), "--flat-tree",
                                   optimize["flat"]["tree"].get<std::string>(), "--frames",
                                   std::to_string(frames), "--width", std::to_string(o.width), "--height",
                                   std::to_string(o.height), "--ao", std::to_string(o.aoRays), "--layout", layout};
  if (layout != "bvh2") argv.insert(argv.end(), {"--tlas", "refit", "--no-rebuild-reference"});
  const ProcessResult r = runProcess(argv, report.string());
  if (!r.ok())
    throw tsah::Failure(scene.input + ": " + o.gpuTwoLevelProgram + " failed" +
                        (r.output.empty() ? "" : ": " + r.output.substr(0, r.output.find('\n'))));
  std::ifstream in(report);
  json j = json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.contains("median") || !j.contains("flat"))
    throw tsah::Failure(scene.input + ": unreadable " + o.gpuTwoLevelProgram + " report " + report.string());
  j["command"] = argv;
  return j;
}

}  // namespace

json runTwoLevelComparison(const SceneSource& scene, const anim::Animation& baked, const BenchOptions& o,
                           const fs::path& outDir, const BenchProgress& progress) {
  if (o.program.empty()) throw tsah::ConfigError("two-level part: the tsah program that optimizes is not set");
  auto say = [&](const std::string& m) { progress(scene.name + ": " + m, false); };
  json j;
  j["scene_file"] = scene.input;

  // --- Optimization: the flat tree and the two-level structure, each one `tsah optimize` -------
  std::error_code ec;
  const fs::path trees = outDir / "trees";
  fs::create_directories(trees, ec);
  if (ec) throw tsah::Failure(trees.string() + ": cannot create the tree folder (" + ec.message() + ")");
  say("tsah optimize --structure flat");
  const json flatOptimize = optimizeChild(scene, "flat", trees / (scene.name + "-flat.tbvh"), o);
  // The two-level structure auto chooses (objects flattened by cost); when it flattens every
  // object (a flat tree), every object kept as instances instead, so that there are two levels.
  say("tsah optimize --structure auto");
  json twoOptimize = optimizeChild(scene, "auto", trees / (scene.name + "-two-level.tbvh"), o);
  if (twoOptimize["structure"] != "two-level") {
    say("tsah optimize --structure two-level (auto chose a flat tree)");
    twoOptimize = optimizeChild(scene, "two-level", trees / (scene.name + "-two-level.tbvh"), o);
    twoOptimize["auto_chose"] = "flat";
  }
  j["optimize"] = {{"flat", flatOptimize}, {"two_level", twoOptimize}};

  anim::LoadOptions load;
  load.fps = o.fps;
  load.clip = o.clip;
  load.resolveDataPath = o.resolveDataPath;
  const Bvh flatTree = loadBvhFile(flatOptimize["tree"].get<std::string>()).bvh;
  const TwoLevelScene twoLevel =
      loadTwoLevelSceneFile(twoOptimize["tree"].get<std::string>(), anim::loadSceneSources(scene.input, load));
  uint64_t triangles = 0;
  for (const anim::SceneSourceInstance& instance : twoLevel.scene.instances)
    triangles += twoLevel.scene.sourceOf(instance).triangleCount();
  if (triangles != baked.triangleCount())
    throw tsah::Failure(scene.input + ": the instances hold " + std::to_string(triangles) +
                        " triangles, the baked scene " + std::to_string(baked.triangleCount()));
  uint32_t staticBlas = 0;
  for (const Blas& b : twoLevel.blases) staticBlas += b.animated ? 0 : 1;
  j["instances"] = twoLevel.instanceCount();
  j["sources"] = twoLevel.blases.size();
  j["static_sources"] = staticBlas;
  j["poses"] = twoLevel.poses.size();
  j["tlas_trees"] = twoLevel.tlases.size();
  j["triangles"] = baked.triangleCount();
  j["structure_bytes"] = twoLevel.memoryBytes();

  // --- Per frame: every tracer on the same rays ---------------------------------------------------
  RuntimeSetup setup = runtimeSetupFor(baked, tracedFrames(twoLevel.frameTimes, o.traceFrames), o,
                                       [&](const std::string& m) { progress(scene.name + ": " + m, true); });
  const std::unique_ptr<CpuRuntime> flat = makeRuntime(baked, flatTree, setup, setup.layout);
  TwoLevelRuntime two(twoLevel, {o.threads, TwoLevelRuntime::TlasUpdate::Refit, setup.layout});
  const Workers flatWorkers = workersOf(*flat);
  const Workers twoWorkers = workersOf(two);
  j["frames"] = setup.times.size();
  j["frame_times"] = setup.times;
  j["width"] = o.width;
  j["height"] = o.height;
  j["ao_rays"] = o.aoRays;
  j["shadow_rays"] = o.shadowRays;
  j["layout"] = name(setup.layout);
  j["threads"] = flat->threadCount();
  j["embree_status"] = embreeStatus();
  j["two_level_runtime_bytes"] = two.memoryBytes();
  std::vector<RuntimeMethod> methods;
  methods.push_back({"flat", "flat tree (T-SAH), " + std::string(name(setup.layout)), "refit", {}, json::object()});
  methods.push_back({"two-level", "two-level (TLAS refit), BLAS " + std::string(name(setup.layout)),
                     "pose refits, transforms, TLAS refit", {}, json::object()});
  std::array<Agreement, 3> agreement;  // two-level vs flat, Embree vs flat, Embree vs two-level
  json tlasRebuildMs = json::array(), blasRefits = json::array(), embreeRefits = json::array();
  json workersNotAwake = json::array();  // per frame: timed updates whose pool was not all awake (startWorkers)
#if TSAH_HAVE_EMBREE
  auto parallelFor = [&flat](std::size_t n, const std::function<void(std::size_t, std::size_t)>& body) {
    flat->parallelFor(n, 1, body);
  };
  EmbreeInstancedPeer embree(twoLevel, flat->threadCount(), parallelFor);
  startWorkers(*flat);
  const double embreeBuildMs = embree.build(setup.times.front());
  j["embree_build"] = {{"ms", embreeBuildMs}, {"object_scenes", embree.objectScenes()}};
  methods.push_back({"embree-instanced", "Embree instancing (pose refits, top level committed)",
                     "pose refits, transforms, top-level commit", {}, json::object()});
#endif

  std::vector<float> positions = baked.positionsAt(baked.startTime());  // static vertices once
  // The flat tree's first, full refit, untimed as the two-level structure and Embree's scenes are
  // built before the frames: each frame then refits what moves (CpuRuntime::Config::movingVertices).
  flat->update(positions);
  RenderSettings settings = setup.settings;
  for (std::size_t f = 0; f < setup.times.size(); ++f) {
    reportFrame(setup, "flat, two-level, Embree instancing", f);
    const double t = setup.times[f];
    settings.frame = static_cast<uint32_t>(f);
    uint32_t wakesMissed = startWorkers(flatWorkers) ? 0 : 1;
    auto start = std::chrono::steady_clock::now();
    baked.movingPositionsAt(t, positions);
    flat->update(positions);
    const double flatUpdateMs = msSince(start);
    const RayBatch batch = makeRayBatch(*flat, setup.camera(t), setup.lighting, settings);  // untimed
    std::array<BatchTrace, 3> traces;
    // The methods in an order rotated every frame: none always runs first or last. Each updates
    // and traces on one pool of threads, as an engine would: the flat tree and Embree on the flat
    // runtime's, the two-level runtime on its own (it updates there). Every timed update starts
    // with that pool's threads awake.
    for (std::size_t k = 0; k < methods.size(); ++k) {
      const std::size_t m = (k + f) % methods.size();
      const Workers& workers = m == 1 ? twoWorkers : flatWorkers;
      wakesMissed += startWorkers(workers) ? 0 : 1;
      double updateMs = flatUpdateMs;
      if (m == 0) {
        traces[m] = traceBatch(workers, batch, toolkitTracer(*flat));
      } else if (m == 1) {
        start = std::chrono::steady_clock::now();
        two.update(t);
        updateMs = msSince(start);
        traces[m] = traceBatch(workers, batch, twoLevelTracer(two));
      } else {
#if TSAH_HAVE_EMBREE
        updateMs = embree.update(t);
        traces[m] = traceBatch(workers, batch, embree.tracer());
#endif
      }
      methods[m].frames.push_back(frameOf(t, updateMs, traces[m]));
    }
    agreement[0].add(traces[0], traces[1]);
    blasRefits.push_back(two.lastUpdateBlasRefits());
    workersNotAwake.push_back(wakesMissed);
#if TSAH_HAVE_EMBREE
    agreement[1].add(traces[0], traces[2]);
    agreement[2].add(traces[1], traces[2]);
    embreeRefits.push_back(embree.lastUpdateRefits());
#endif
    // The per-frame reference of the TLAS refit: a sweep-SAH TLAS over this frame's instance boxes.
    start = std::chrono::steady_clock::now();
    const Bvh rebuilt = rebuildTlas(two.instanceBoxes(), twoLevel.objective);
    tlasRebuildMs.push_back(msSince(start));
    (void)rebuilt;
  }
  methods[1].extra = {{"agreement_with_flat", toJson(agreement[0])},
                      {"blas_refits_per_frame", blasRefits},
                      {"tlas_rebuild_ms_per_frame", tlasRebuildMs}};
  json ratios = {{"two_level_rate_over_flat_rate", ratio(traceRate(methods[1]), traceRate(methods[0]))},
                 {"two_level_total_over_flat_total", ratio(averageTotalMs(methods[1]), averageTotalMs(methods[0]))}};
#if TSAH_HAVE_EMBREE
  methods[2].extra = {{"agreement_with_flat", toJson(agreement[1])},
                      {"agreement_with_two_level", toJson(agreement[2])},
                      {"pose_refits_per_frame", embreeRefits}};
  ratios["two_level_total_over_embree_total"] = ratio(averageTotalMs(methods[1]), averageTotalMs(methods[2]));
  ratios["two_level_rate_over_embree_rate"] = ratio(traceRate(methods[1]), traceRate(methods[2]));
#endif
  j["ratios"] = ratios;
  j["wakes_missed_per_frame"] = workersNotAwake;
  j["methods"] = json::array();
  for (const RuntimeMethod& m : methods) j["methods"].push_back(toJson(m));
  if (!o.gpuTwoLevelProgram.empty()) {
    say("GPU: " + fs::path(o.gpuTwoLevelProgram).filename().string());
    j["gpu"] = gpuFigures(scene, j["optimize"], setup.times.size(), o, "bvh2");
    j["gpu_cwbvh"] = gpuFigures(scene, j["optimize"], setup.times.size(), o, "cwbvh");
  }
  return j;
}

}  // namespace tsah::bench
