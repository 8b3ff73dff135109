#include "bench/bench.hpp"

#include <sys/utsname.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <mutex>
#include <thread>

#include "tsah/base/error.hpp"
#include "tsah/base/work_dealer.hpp"
#include "anim/load.hpp"
#include "anim/scene.hpp"
#include "bench/embree_peer.hpp"
#include "bench/motion_bench.hpp"
#include "bench/runtime_bench.hpp"
#include "frame_runtime.hpp"
#include "animation_frames.hpp"
#include "bench/segments.hpp"
#include "bench/two_level_bench.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/camera_path.hpp"
#if TSAH_HAVE_CUDA
#include "tsah_cuda/gpu_optimizer.hpp"
#endif
#include "tsah/render/image.hpp"

#ifndef TSAH_VERSION
#define TSAH_VERSION "unknown"
#endif

namespace tsah::bench {

namespace fs = std::filesystem;

namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The first line of /proc/cpuinfo or /etc/os-release that starts with `key`, its value unquoted.
std::string fileValue(const char* path, const std::string& key, char separator) {
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) != 0) continue;
    const std::size_t at = line.find(separator);
    if (at == std::string::npos) continue;
    std::string value = line.substr(at + 1);
    while (!value.empty() && (value.front() == ' ' || value.front() == '\t' || value.front() == '"')) value.erase(0, 1);
    while (!value.empty() && (value.back() == ' ' || value.back() == '"')) value.pop_back();
    return value;
  }
  return {};
}

// Half size (2x2 box filter) for the report's picture; small images stay as they are.
Image halfSize(const Image& in) {
  if (in.width < 512) return in;
  Image out(in.width / 2, in.height / 2);
  for (uint32_t y = 0; y < out.height; ++y)
    for (uint32_t x = 0; x < out.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const unsigned sum = in.pixel(2 * x, 2 * y)[c] + in.pixel(2 * x + 1, 2 * y)[c] + in.pixel(2 * x, 2 * y + 1)[c] +
                             in.pixel(2 * x + 1, 2 * y + 1)[c];
        out.pixel(x, y)[c] = static_cast<uint8_t>((sum + 2) / 4);
      }
  return out;
}

// "0.5 centered": the shutter as the progress line names it.
std::string formatShutter(const Shutter& shutter) {
  char text[48];
  std::snprintf(text, sizeof text, "%g %s", shutter.fraction, shutter.mode == Shutter::Mode::Open ? "open" : "centered");
  return text;
}

const std::vector<std::string> kTable1Methods = {"rebuild", "sahstar", "sah0", "tsah0", "tsah2", "tsah4"};

tsah::BaselineConfig baselineConfig(const BenchOptions& o, const BenchProgress& progress) {
  tsah::BaselineConfig config;
  config.objective = o.objective;
  config.threads = o.threads;
  config.optimizer.seed = o.seed;
  if (o.optimizer == "cuda") {  // the GPU parallel reinsertion optimizer
#if TSAH_HAVE_CUDA
    config.deviceOptimizer = cuda::gpuTreeOptimizer();
#else
    throw tsah::ConfigError("--optimizer cuda: this build of tsah has no CUDA support");
#endif
  } else {
    config.optimizerKind = parse<OptimizerKind>(o.optimizer);
  }
  config.parallel.threads = o.threads;
  config.progress = [progress](const std::string& message) { progress(message, true); };
  return config;
}

nlohmann::json historyJson(const InsertionOptimizer::Result& r) {
  nlohmann::json history = nlohmann::json::array();
  for (const auto& b : r.history)
    history.push_back({{"batch", b.batch}, {"elapsed_s", b.elapsedSeconds}, {"average", b.averageCost}, {"cost", b.cost},
                       {"steps", b.steps}});
  return history;
}

}  // namespace

std::string methodLabel(const std::string& id) {
  if (id == "rebuild") return "SAH-rebuild";
  if (id == "sahstar") return "SAH*";
  if (id == "sah0") return "SAH0";
  if (id.rfind("tsah", 0) == 0) return "T-SAH k=" + id.substr(4);
  return id;
}

RuntimeSetup runtimeSetupFor(const anim::Animation& a, std::vector<double> times, const BenchOptions& o,
                             std::function<void(const std::string&)> progress) {
  RuntimeSetup setup;
  setup.times = std::move(times);
  const anim::Bounds ab = a.bounds();
  Aabb bounds;
  bounds.extend(Vec3{ab.min[0], ab.min[1], ab.min[2]});
  bounds.extend(Vec3{ab.max[0], ab.max[1], ab.max[2]});
  const Vec3 up{0, 1, 0};
  std::vector<anim::CameraKey> path(a.cameraPath().begin(), a.cameraPath().end());
  const Camera fitted = fitCamera(bounds, up, 45.0f, float(o.width) / float(o.height));
  setup.camera = [path, fitted](double t) { return path.empty() ? fitted : cameraAt(path, t); };
  setup.lighting = fitLighting(bounds, setup.camera(setup.times.front()), up, 0.1f, o.ground);
  setup.settings.width = o.width;
  setup.settings.height = o.height;
  setup.settings.aoSamples = o.aoRays;
  setup.settings.shadowSamples = o.shadowRays;
  setup.settings.seed = static_cast<uint32_t>(o.seed);
  setup.threads = o.threads;
  setup.layout = o.layout == Layout::Auto || o.device == Device::Cuda ? fastestLayout() : o.layout;
  setup.collapse.cost = o.objective.cost;
  setup.collapse.maxLeafSize = o.objective.maxLeafSize;
  setup.progress = std::move(progress);
  return setup;
}

nlohmann::json benchScene(const SceneSource& scene, const BenchOptions& o, const fs::path& outDir,
                          const BenchProgress& progress) {
  auto say = [&](const std::string& m) { progress(scene.name + ": " + m, false); };
  nlohmann::json j;
  j["name"] = scene.name;
  j["input"] = scene.input;
  j["kind"] = scene.kind;
  j["origin"] = scene.origin;

  // --- Load ---------------------------------------------------------------------------------
  say("loading " + scene.input);
  auto start = std::chrono::steady_clock::now();
  std::vector<std::string> warnings;
  anim::LoadOptions load;
  load.fps = o.fps;
  load.clip = o.clip;
  load.resolveDataPath = o.resolveDataPath;
  load.warning = [&warnings](const std::string& w) { warnings.push_back(w); };
  anim::Animation a = anim::load(scene.input, load);
  j["load_s"] = secondsSince(start);
  j["warnings"] = warnings;
  if (a.keyframeCount() < 2) throw NotAnAnimation(scene.input + ": one keyframe (a static scene, not an animation)");
  if (a.triangleCount() == 0) throw tsah::DataError(scene.input + ": no triangles");
  j["triangles"] = a.triangleCount();
  j["vertices"] = a.vertexCount();
  j["keyframes"] = a.keyframeCount();
  j["time_start"] = a.startTime();
  j["time_end"] = a.endTime();
  say(std::to_string(a.triangleCount()) + " triangles, " + std::to_string(a.keyframeCount()) + " keyframes");
  // The two-level part of a scene file (CPU); --two-level-only: that part alone.
  const bool sceneFile = anim::isSceneFile(scene.input);
  auto twoLevelPart = [&] {
    if (!sceneFile) return;
    if (o.device != Device::Cpu) {
      j["two_level"] = {{"skipped", "the two-level part runs on the CPU (the GPU's: tsah_two_level_gpu_bench)"}};
      return;
    }
    say("two-level part: flat tree, two-level structure and Embree instancing on the same rays");
    start = std::chrono::steady_clock::now();
    j["two_level"] = runTwoLevelComparison(scene, a, o, outDir, progress);
    j["two_level"]["wall_s"] = secondsSince(start);
  };
  if (o.twoLevelOnly) {
    twoLevelPart();
    say("done");
    return j;
  }

  const anim::Animation rep = a.resample(o.frames);
  const PrimitiveBoxes repBoxes = triangleBoxes(rep.indices(), rep.allPositions(), o.frames);
  const std::vector<double> evalTimes = a.uniformTimes(o.evalFrames);
  const FrameSource evaluation = tsah::cli::animationFrames(a, evalTimes);
  const BaselineConfig config = baselineConfig(o, progress);

  // --- Table 1 ------------------------------------------------------------------------------
  std::vector<MethodResult> table1;
  // --embree-only and --motion-blur-only: the T-SAH tree and their comparison alone.
  const bool comparisonOnly = o.embreeOnly || o.motionBlurOnly;
  if (!comparisonOnly) {
    say("Table 1: SAH-rebuild, SAH*, SAH0, T-SAH k=0/2/4 over " + std::to_string(o.evalFrames) + " frames");
    start = std::chrono::steady_clock::now();
    std::vector<MethodSpec> specs;
    for (const std::string& id : kTable1Methods) specs.push_back(MethodSpec::parse(id));
    table1 = compareMethods(specs, repBoxes, evaluation, config);
    nlohmann::json t1;
    t1["frames"] = o.frames;
    t1["eval_frames"] = o.evalFrames;
    t1["eval_times"] = evalTimes;
    t1["wall_s"] = secondsSince(start);
    t1["methods"] = nlohmann::json::array();
    for (std::size_t m = 0; m < table1.size(); ++m)
      t1["methods"].push_back({{"name", kTable1Methods[m]},
                               {"label", methodLabel(kTable1Methods[m])},
                               {"build_s", table1[m].buildSeconds},
                               {"average", table1[m].average},
                               {"maximum", table1[m].maximum},
                               {"per_frame", table1[m].perFrame}});
    j["table1"] = t1;
  }

  // --- Trees for the runtime, convergence of the three node selections ------------------------
  // The Metropolis-Hastings run is the T-SAH k=0 tree of Table 1 (same seed, same tree).
  using Selection = InsertionOptimizer::Selection;
  const std::vector<std::pair<std::string, Selection>> selections = {
      {"mh", Selection::MetropolisHastings}, {"random", Selection::Uniform}, {"batch", Selection::BatchSort}};
  Bvh tsahTree;
  j["convergence"] = nlohmann::json::array();
  for (const auto& [id, selection] : selections) {
    if (id != "mh" && (!o.convergence || comparisonOnly)) continue;
    say("T-SAH k=0 optimization, " + id + " node selection");
    BaselineConfig c = config;
    c.optimizer.selection = selection;
    InsertionOptimizer::Result details;
    start = std::chrono::steady_clock::now();
    Bvh tree = buildTSah(repBoxes, 0, c, &details);
    const double wall = secondsSince(start);
    j["convergence"].push_back({{"selection", id},
                                {"label", id == "mh"       ? "Metropolis-Hastings"
                                          : id == "random" ? "random"
                                                           : "batch sorting"},
                                {"initial_cost", details.initialCost},
                                {"final_cost", details.finalCost},
                                {"seconds", details.seconds},
                                {"build_wall_s", wall},
                                {"steps", details.steps},
                                {"accepted_steps", details.acceptedSteps},
                                {"history", historyJson(details)}});
    if (id == "mh") tsahTree = std::move(tree);
  }
  say("SAH0 and SAH* trees for the runtime");
  const Bvh sah0Tree = comparisonOnly ? Bvh{} : buildSah0(repBoxes, config);
  const Bvh sahStarTree = comparisonOnly ? Bvh{} : buildSahStar(repBoxes, config);

  // --- Segments: equal-time parts, count and budget modes (tsah/segmentation.hpp) -------------
  SegmentRuns segmentRuns;
  if ((o.segments > 1 || o.budget > 0.0) && !comparisonOnly) {  // no Table 1 to compare with
    SegmentExperiment experiment;
    experiment.count = o.segments;
    experiment.budget = o.budget;
    experiment.frames = o.frames;
    experiment.evalFrames = o.evalFrames;
    experiment.rebuildCosts = table1[0].perFrame;  // kTable1Methods[0]: SAH-rebuild
    experiment.oneTreeCosts = table1[3].perFrame;  // tsah0
    experiment.oneTreeBuildSeconds = table1[3].buildSeconds;
    nlohmann::json segments;
    segmentRuns = runSegmentExperiment(a, experiment, config, segments, say);
    j["segments"] = segments;
  }

  // --- Runtime ----------------------------------------------------------------------------------
  RuntimeSetup setup = runtimeSetupFor(a, a.uniformTimes(o.traceFrames), o,
                                       [&](const std::string& m) { progress(scene.name + ": " + m, true); });
  std::vector<anim::CameraKey> path(a.cameraPath().begin(), a.cameraPath().end());

  const bool gpu = o.device == Device::Cuda;
  RefitTrees sah0{"sah0", "SAH0 refit", {&sah0Tree}, {}};
  RefitTrees sahStar{"sahstar", "SAH* refit", {&sahStarTree}, {}};
  RefitTrees tsah{"tsah0", "T-SAH k=0 refit", {&tsahTree}, {}};
  // Tree sets: one runtime per method switches to the tree of each frame's part.
  auto setOf = [](const std::string& name, const std::string& label, const SegmentationResult& r) {
    RefitTrees t{name, label, {}, r.buildRanges};
    for (const Bvh& tree : r.trees) t.trees.push_back(&tree);
    return t;
  };
  const std::string k = std::to_string(o.segments);
  if (!comparisonOnly)
    say(std::string("Table 2 on the ") + (gpu ? "GPU" : "CPU") + ": " + std::to_string(setup.times.size()) +
        " frames at " + std::to_string(o.width) + "x" + std::to_string(o.height) + ", 1 primary + " +
        std::to_string(o.aoRays) + " AO + " + std::to_string(o.shadowRays) + " shadow rays per pixel");
  nlohmann::json runtime;
  runtime["device"] = gpu ? "cuda" : "cpu";
  runtime["layout"] = name(gpu ? gpuLayout(o.layout) : setup.layout);
  runtime["frames"] = setup.times.size();
  runtime["width"] = o.width;
  runtime["height"] = o.height;
  runtime["ao_rays"] = o.aoRays;
  runtime["shadow_rays"] = o.shadowRays;
  runtime["ground"] = o.ground;
  runtime["camera"] = path.empty() ? "fitted to the animation bounds" : "the animation's camera path";
  runtime["methods"] = nlohmann::json::array();
  start = std::chrono::steady_clock::now();
  Image picture;
  const uint32_t pictureFrame = static_cast<uint32_t>(setup.times.size() / 2);
  std::vector<RefitTrees> refits = {sah0, sahStar, tsah};
  if (!segmentRuns.equal.trees.empty())
    refits.push_back(setOf("tsah0-seg" + k, "T-SAH k=0 refit, " + k + " equal-time trees", segmentRuns.equal));
  if (!segmentRuns.count.trees.empty())
    refits.push_back(setOf("tsah0-count" + k, "T-SAH k=0 refit, " + k + " trees (count mode)", segmentRuns.count));
  if (!segmentRuns.budget.trees.empty())
    refits.push_back(setOf("tsah0-budget",
                           "T-SAH k=0 refit, budget mode (" + std::to_string(segmentRuns.budget.trees.size()) + " trees)",
                           segmentRuns.budget));
  if (comparisonOnly) {
    runtime["skipped"] = o.embreeOnly ? "--embree-only" : "--motion-blur-only";
  } else if (gpu) {
    const std::string gpuLayoutName = o.layout == Layout::Auto ? std::string() : name(o.layout);
    // The methods (the refits, then the two rebuilds) dealt to the GPUs of --devices: each
    // method's frames on one GPU, so its figures are one GPU's.
    const std::vector<int> gpus = o.devices.empty() ? std::vector<int>{0} : o.devices;
    const std::size_t methodCount = refits.size() + 2;
    std::vector<RuntimeMethod> done(methodCount);
    std::mutex progressLock;
    RuntimeSetup shared = setup;
    shared.progress = [&](const std::string& m) {
      const std::lock_guard lock(progressLock);
      setup.progress(m);
    };
    ThreadDealer dealer(unsigned(gpus.size()));
    dealer.deal(unitRange(0, uint32_t(methodCount)), [&](uint32_t m, unsigned worker) {
      RuntimeSetup mine = shared;
      mine.gpu = gpus[worker];
      if (m < refits.size())
        done[m] = runGpuRefit(a, refits[m], mine, refits[m].name == "tsah0" ? &picture : nullptr, pictureFrame,
                              gpuLayoutName);
      else
        done[m] = runGpuRebuild(a, tsahTree, m == refits.size() ? "lbvh" : "hlbvh-sah", config.objective.cost,
                                config.objective.maxLeafSize, mine, gpuLayoutName);
      return UnitResult();
    });
    for (const RuntimeMethod& m : done) runtime["methods"].push_back(toJson(m));
    runtime["schedule"] = gpus.size() > 1 ? "methods dealt to " + std::to_string(gpus.size()) +
                                                " GPUs, each method on one (device times from CUDA events)"
                                          : "method by method (device times from CUDA events)";
  } else {
    std::vector<CpuMethodSpec> cpuMethods;
    for (const RefitTrees& r : refits) cpuMethods.push_back({r, std::nullopt});
    cpuMethods.push_back({{"rebuild-sweep", "sweep SAH rebuild", {&tsahTree}, {}}, CpuRebuild::Sweep});
    cpuMethods.push_back({{"rebuild-binned", "binned SAH rebuild", {&tsahTree}, {}}, CpuRebuild::Binned});
    runtime["schedule"] = "frame by frame: every method on a frame before the next, in an order rotated every frame";
    const std::size_t tsahIndex = 2;  // cpuMethods: sah0, sahstar, tsah0, ...
    for (const RuntimeMethod& m : runCpuMethods(a, cpuMethods, config.objective.cost, config.objective.maxLeafSize, setup, &picture, tsahIndex, pictureFrame))
      runtime["methods"].push_back(toJson(m));
  }
  runtime["wall_s"] = secondsSince(start);
  if (!comparisonOnly) j["runtime"] = runtime;
  if (picture.width > 0) {
    std::error_code ec;
    fs::create_directories(outDir / "images", ec);
    const std::string file = "images/" + scene.name + ".png";
    savePng((outDir / file).string(), halfSize(picture));
    j["image"] = {{"file", file},
                  {"time", setup.times[pictureFrame]},
                  {"method", "tsah0"},
                  {"note", picture.width >= 512 ? "traced at full size, stored at half size" : "as traced"}};
  }

  // --- Embree peer (CPU) ------------------------------------------------------------------------
  nlohmann::json peer;
  peer["status"] = embreeStatus();
  if (o.motionBlurOnly) {
    peer["skipped"] = "--motion-blur-only";
  } else if (!gpu && o.embree && embreeAvailable()) {
    say("the toolkit's T-SAH refit against Embree on the same rays");
    start = std::chrono::steady_clock::now();
    peer["frames"] = setup.times.size();
    peer["methods"] = nlohmann::json::array();
    // The tree set of the count mode (K trees; computed here with --embree-only), traced as well.
    SegmentationResult countSet = segmentRuns.count;
    if (countSet.trees.empty() && o.segments > 1) {
      say("count mode: split points for " + std::to_string(o.segments) + " trees (the toolkit's tree set)");
      countSet = countModeTrees(a, o.segments, o.frames, o.evalFrames, config);
    }
    const RefitTrees set = setOf("tsah0-count" + k, "toolkit: T-SAH k=0 refit, " + k + " trees (count mode)", countSet);
    for (const RuntimeMethod& m :
         runEmbreeComparison(a, tsahTree, "tsah0", "toolkit: T-SAH k=0 refit", setup, countSet.trees.empty() ? nullptr : &set))
      peer["methods"].push_back(toJson(m));
    peer["wall_s"] = secondsSince(start);
  } else if (gpu) {
    peer["skipped"] = "the Embree peer runs with --device cpu";
  } else if (!o.embree) {
    peer["skipped"] = "--no-embree";
  }
  j["embree"] = peer;

  // --- Motion blur (CPU): the toolkit's blurred frames against Embree's motion-blur BVH -----------
  if (o.shutter.fraction > 0.0) {
    say("motion blur: shutter " + formatShutter(o.shutter) + ", the toolkit against Embree's motion-blur BVH");
    start = std::chrono::steady_clock::now();
    nlohmann::json blur = runMotionBlurComparison(a, tsahTree, "toolkit: T-SAH k=0 refit", setup, o.shutter);
    blur["wall_s"] = secondsSince(start);
    j["motion_blur"] = blur;
  }
  if (!comparisonOnly) twoLevelPart();  // --embree-only and --motion-blur-only: their comparison alone
  say("done");
  return j;
}

nlohmann::json machineJson(bool withGpu) {
  nlohmann::json m;
  std::string cpu = fileValue("/proc/cpuinfo", "model name", ':');
  m["cpu"] = cpu.empty() ? "unknown" : cpu;
  m["logical_cores"] = std::thread::hardware_concurrency();
  const std::string memory = fileValue("/proc/meminfo", "MemTotal", ':');  // "24531232 kB"
  if (!memory.empty()) m["memory_gib"] = std::stod(memory) / (1024.0 * 1024.0);
  m["os"] = fileValue("/etc/os-release", "PRETTY_NAME", '=');
  struct utsname u;
  if (::uname(&u) == 0) m["kernel"] = std::string(u.sysname) + " " + u.release + " " + u.machine;
  if (withGpu) m["gpu"] = cli::deviceJson();
  return m;
}

nlohmann::json versionsJson() {
  nlohmann::json v;
  v["tsah"] = TSAH_VERSION;
#if defined(__clang__)
  v["compiler"] = std::string("clang ") + __clang_version__;
#elif defined(__GNUC__)
  v["compiler"] = std::string("GCC ") + __VERSION__;
#else
  v["compiler"] = "unknown";
#endif
#ifdef NDEBUG
  v["build"] = "optimized (NDEBUG)";
#else
  v["build"] = "debug (assertions on)";
#endif
  v["embree"] = embreeStatus();
#if TSAH_HAVE_CUDA
  v["cuda_runtime_built"] = true;
#else
  v["cuda_runtime_built"] = false;
#endif
  return v;
}

nlohmann::json optionsJson(const BenchOptions& o) {
  return {{"device", name(o.device)},     {"quick", o.quick},          {"seed", o.seed},
          {"frames", o.frames},     {"eval_frames", o.evalFrames}, {"trace_frames", o.traceFrames},
          {"width", o.width},       {"height", o.height},        {"ao_rays", o.aoRays},
          {"shadow_rays", o.shadowRays}, {"ground", o.ground},   {"max_leaf", o.objective.maxLeafSize},
          {"ct", o.objective.cost.ct}, {"ci", o.objective.cost.ci},                {"segments", o.segments},   {"budget", o.budget},
          {"threads", o.threads},   {"embree", o.embree},        {"convergence", o.convergence},
          {"optimizer", o.optimizer},
          {"layout", name(o.layout)},     {"embree_only", o.embreeOnly},
          {"shutter", o.shutter.fraction}, {"shutter_mode", o.shutter.mode == Shutter::Mode::Open ? "open" : "centered"},
          {"motion_blur_only", o.motionBlurOnly}, {"two_level_only", o.twoLevelOnly}};
}

}  // namespace tsah::bench
