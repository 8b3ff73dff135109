// tsah bench [SCENES...] [--data DIR] [--device cpu|cuda] [--out DIR] [--quick] [--seed S]
//   [--frames N] [--eval-frames M] [--trace-frames T] [--scene-dir DIR] [--two-level-only] ...
// The paper's evaluation (Tables 1 and 2, Figures 3-6), the segmenting experiment and the Embree
// peer on every real animation of the data folder (or the scenes named), and the two-level part of
// every scene file (--scene-dir: flat tree, two-level runtime, Embree instancing), into OUT/results.json,
// OUT/results.md and OUT/plots/*.png. The work is in apps/bench/; this file is the command line.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <cstdlib>
#include <memory>
#include <nlohmann/json.hpp>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "bench/bench.hpp"
#include "scale_out.hpp"
#include "bench/data_scan.hpp"
#include "bench/embree_peer.hpp"
#include "bench/paper.hpp"
#include "bench/report.hpp"
#include "bench/runtime_bench.hpp"
#include "bench/scaling.hpp"
#include "anim/scene.hpp"
#include "cli.hpp"
#include "frame_runtime.hpp"
#if TSAH_HAVE_CUDA
#include "tsah_cuda/device.hpp"
#endif

#ifndef TSAH_SOURCE_DIR
#define TSAH_SOURCE_DIR ""
#endif

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using tsah::cli::UsageError;

struct Options {
  std::vector<std::string> scenes;
  std::string sceneDir;  // composed scenes (*.json scene files, docs/scenes.md) benchmarked with the data
  std::string data, out = "bench", cache;
  std::vector<std::string> notes;
  tsah::bench::BenchOptions bench;
  std::string devices;  // --devices all|0,2,...
  bool list = false, reportOnly = false, noEmbree = false, noConvergence = false;
  tsah::cli::ShutterOptions shutter;  // --shutter, --shutter-mode: the motion-blur part
  bool twoLevelGpu = false;  // --two-level-gpu: the two-level part's GPU figures (tsah_two_level_gpu_bench)
  bool scaling = false;  // --scaling: the optimizers' scaling mode (bench/scaling.hpp) instead
  tsah::bench::ScalingOptions scalingOptions;
};

// Progress on stderr, one line per message with the elapsed time; frequent detail messages
// (optimizer batches, frames) at most every 10 seconds.
class ProgressLog {
 public:
  void operator()(const std::string& message, bool detail) {
    const auto now = std::chrono::steady_clock::now();
    if (detail && now - lastDetail_ < std::chrono::seconds(10)) return;
    if (detail) lastDetail_ = now;
    const double s = std::chrono::duration<double>(now - start_).count();
    std::fprintf(stderr, "[bench %7.1fs] %s\n", s, message.c_str());
    std::fflush(stderr);
  }

 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point lastDetail_{};
};

std::string nowText() {
  const std::time_t t = std::time(nullptr);
  char text[64];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M:%S %Z", std::localtime(&t));
  return text;
}

// The command line as typed (Linux: /proc/self/cmdline), the program shown as `tsah`.
std::string commandLine() {
  std::ifstream in("/proc/self/cmdline", std::ios::binary);
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::string out;
  std::size_t start = 0;
  bool first = true;
  while (start < all.size()) {
    std::size_t end = all.find('\0', start);
    if (end == std::string::npos) end = all.size();
    std::string arg = all.substr(start, end - start);
    if (first) arg = "tsah";
    if (arg.find_first_of(" \t'\"$") != std::string::npos) arg = "'" + arg + "'";
    out += (first ? "" : " ") + arg;
    first = false;
    start = end + 1;
  }
  return out.empty() ? "tsah bench" : out;
}

// A report's JSON and the markdown made from it are one output set: both appear, or neither.
void writeReportPair(const fs::path& jsonPath, const std::string& jsonText, const fs::path& md, const std::string& mdText) {
  tsah::AtomicFileSet files;
  files.write(jsonPath.string(), jsonText);
  files.write(md.string(), mdText);
  files.commit();
}

void writeReport(const fs::path& out, const json& results) {
  writeReportPair(out / "results.json", results.dump(1) + "\n", out / "results.md", tsah::bench::renderMarkdown(results));
}

void makePlotsInto(json& results, const fs::path& out, ProgressLog& log) {
  log("plots", false);
  const tsah::bench::PlotOutcome plots = tsah::bench::makePlots(results, out);
  results["plots"] = {{"status", plots.status}, {"files", plots.files}};
  log("plots: " + plots.status, false);
}

void reportOnly(const Options& opt) {
  ProgressLog log;
  const fs::path out = opt.out;
  const std::string file = (out / "results.json").string();
  const std::vector<uint8_t> bytes = tsah::readFileForUpdate(file, std::size_t(1) << 30);  // rewritten below
  json results;
  try {
    results = json::parse(bytes.begin(), bytes.end());
  } catch (const json::exception& e) {
    throw tsah::FileError(file, std::string("not valid JSON: ") + e.what());
  }
  if (!results.is_object() || !results.contains("scenes")) throw tsah::FileError(file, "not a tsah bench results file");
  // Notes given now annotate the finished run (what was learned after it, e.g. about the machine).
  if (!results.contains("notes") || !results["notes"].is_array()) results["notes"] = json::array();
  for (const std::string& n : opt.notes) results["notes"].push_back("(added after the run with --report-only) " + n);
  makePlotsInto(results, out, log);
  writeReport(out, results);
  std::printf("%s\n%s\n", (out / "results.md").c_str(), (out / "results.json").c_str());
}

// --scaling: every (input, optimizer) pair as one `tsah optimize` child process of this program.
void runScalingMode(Options& opt, CLI::App* sub, const std::vector<tsah::bench::SceneSource>& scenes, ProgressLog& log) {
  tsah::bench::ScalingOptions& o = opt.scalingOptions;
  const tsah::bench::BenchOptions& b = opt.bench;
  std::error_code ec;
  o.program = fs::read_symlink("/proc/self/exe", ec).string();
  if (ec) throw tsah::Failure("cannot find the tsah program (/proc/self/exe): " + ec.message());
  o.frames = b.frames;
  o.evalFrames = sub->get_option("--eval-frames")->count() > 0 ? b.evalFrames : 10;
  o.seed = b.seed;
  o.threads = b.threads;
#if TSAH_HAVE_CUDA
  if (sub->get_option("--scaling-optimizers")->count() == 0 && tsah::cuda::deviceAvailable())
    o.optimizers.push_back("cuda");
#endif
  const fs::path out = opt.out;
  json results = tsah::bench::runScaling(scenes, o, out, [&](const std::string& m) { log(m, false); });
  results["tool"] = "tsah bench --scaling";
  results["command"] = commandLine();
  results["machine"] = tsah::bench::machineJson(false);
  log("plots", false);
  tsah::bench::makeScalingPlots(results, out);
  writeReportPair(out / "scaling.json", results.dump(1) + "\n", out / "scaling.md",
                  tsah::bench::renderScalingMarkdown(results));
  std::printf("%s\n%s\n", (out / "scaling.md").c_str(), (out / "scaling.json").c_str());
}

// --shutter and --motion-blur-only: the motion-blur part runs on the CPU against Embree, over the
// time between two traced frames or more (checked after --quick has set the frame count).
void checkShutter(const Options& opt, tsah::bench::BenchOptions& b) {
  b.shutter = opt.shutter.checked("the time between traced frames");
  if (b.motionBlurOnly && b.shutter.fraction == 0.0)
    throw UsageError("--motion-blur-only runs the motion-blur part: give --shutter S with S > 0");
  if (b.motionBlurOnly && b.embreeOnly)
    throw UsageError("--motion-blur-only and --embree-only each run one comparison alone: give one of them");
  if (b.shutter.fraction == 0.0) return;
  if (b.device != tsah::Device::Cpu) throw UsageError("--shutter: the motion-blur part runs on the CPU (--device cpu)");
  if (opt.noEmbree) throw UsageError("--shutter compares the toolkit with Embree's motion blur: not with --no-embree");
  if (!tsah::bench::embreeAvailable()) throw UsageError("--shutter: " + tsah::bench::embreeStatus());
  if (b.traceFrames < 2)
    throw UsageError("--shutter needs at least two traced frames (--trace-frames): it is a fraction of the time "
                     "between them");
}

void run(Options opt, CLI::App* sub) {
  using namespace tsah::bench;
  if (opt.reportOnly) return reportOnly(opt);
  BenchOptions& b = opt.bench;
  b.embree = !opt.noEmbree;
  if (b.embreeOnly && (opt.noEmbree || b.device != tsah::Device::Cpu))
    throw UsageError("--embree-only runs the CPU comparison with Embree: not with --no-embree or --device cuda");
  if (b.embreeOnly && !embreeAvailable()) throw UsageError("--embree-only: " + embreeStatus());
  if (b.twoLevelOnly && (b.embreeOnly || b.motionBlurOnly || b.device != tsah::Device::Cpu))
    throw UsageError("--two-level-only runs the two-level part alone, on the CPU: not with --embree-only, "
                     "--motion-blur-only or --device cuda");
  tsah::cli::checkLayoutForDevice(b.layout, b.device);
  b.convergence = !opt.noConvergence;
  const anim::LoadOptions& load = tsah::cli::commandLineLoadOptions();
  b.fps = load.fps;
  b.clip = load.clip;
  // --quick: a smoke run; options given explicitly keep their values.
  auto given = [sub](const char* name) { return sub->get_option(name)->count() > 0; };
  if (b.quick) {
    if (!given("--eval-frames")) b.evalFrames = 10;
    if (!given("--trace-frames")) b.traceFrames = 3;
    if (!given("--width")) b.width = 192;
    if (!given("--height")) b.height = 144;
  }
  checkShutter(opt, b);
  const auto requireGpu = [](const std::string& option) {
    if (tsah::cli::gpuAvailable()) return;
    throw UsageError(option + (versionsJson()["cuda_runtime_built"].get<bool>()
                                   ? ": no CUDA device is available on this machine"
                                   : ": this tsah was built without the CUDA runtime"));
  };
  if (!opt.devices.empty()) {
    if (b.device != tsah::Device::Cuda) throw UsageError("--devices chooses GPUs: use it with --device cuda");
    b.devices = tsah::cli::parseDevices(opt.devices);
  }
  if (b.device == tsah::Device::Cuda) requireGpu("--device cuda");
  if (opt.twoLevelGpu) {  // the GPU figures of the two-level part, by the GPU two-level bench beside tsah
    requireGpu("--two-level-gpu");
    std::error_code exe;
    const fs::path program = fs::read_symlink("/proc/self/exe", exe).parent_path() / "tsah_two_level_gpu_bench";
    if (exe || !fs::exists(program))
      throw UsageError("--two-level-gpu: " + program.string() + " is missing (build the tsah_two_level_gpu_bench target)");
    b.gpuTwoLevelProgram = program.string();
  }
  if (b.optimizer == "cuda") requireGpu("--optimizer cuda");
  ProgressLog log;
  const fs::path out = opt.out;
  const fs::path cache = opt.cache.empty() ? out / "cache" : fs::path(opt.cache);

  // The scene files of --scene-dir, read (and refused when there are none) before any data scan.
  std::vector<SceneSource> sceneFiles;
  if (!opt.sceneDir.empty()) {
    std::vector<std::string> files;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(opt.sceneDir, ec))
      if (e.path().extension() == ".json" && anim::isSceneFile(e.path().string())) files.push_back(e.path().string());
    if (ec) throw UsageError(opt.sceneDir + ": cannot read the scene folder (" + ec.message() + ")");
    if (files.empty())
      throw UsageError(opt.sceneDir + ": no scene files (*.json with \"objects\", docs/scenes.md) in the scene folder");
    std::sort(files.begin(), files.end());
    for (const std::string& f : files) {
      SceneSource s = explicitScene(f);
      s.kind = "scene";
      sceneFiles.push_back(s);
    }
  }
  // Scenes: paths given, names of the data folder's scenes, or every scene found there.
  std::vector<SceneSource> scenes;
  DataScan scan;
  bool scanned = false;
  fs::path dataFolder;
  auto scanData = [&] {
    if (scanned) return;
    dataFolder = defaultDataFolder(opt.data, TSAH_SOURCE_DIR);
    log("scanning " + dataFolder.string(), false);
    scan = scanDataFolder(dataFolder, {cache, [&](const std::string& m) { log(m, false); }});
    scanned = true;
  };
  b.resolveDataPath = tsah::cli::dataPathResolver(opt.data, cache.string());
  for (const std::string& s : opt.scenes) {
    std::error_code ec;
    if (fs::exists(s, ec)) {
      scenes.push_back(explicitScene(s));
      continue;
    }
    scanData();
    const auto it = std::find_if(scan.scenes.begin(), scan.scenes.end(), [&](const SceneSource& x) { return x.name == s; });
    if (it == scan.scenes.end()) {
      std::string names;
      for (const SceneSource& x : scan.scenes) names += (names.empty() ? "" : ", ") + x.name;
      throw UsageError("no scene '" + s + "': not a file or folder, and not a scene of " + dataFolder.string() +
                       " (" + (names.empty() ? "none found" : names) + ")");
    }
    scenes.push_back(*it);
  }
  if (opt.scenes.empty() && opt.scaling) {
    // The scaling mode has its generated inputs: without a data folder it runs on those alone.
    try {
      scanData();
    } catch (const tsah::Error& e) {
      log(std::string("no real scenes: ") + e.what(), false);
    }
    scenes = scan.scenes;
  } else if (opt.scenes.empty() && !(b.twoLevelOnly && !opt.sceneDir.empty())) {
    scanData();
    scenes = scan.scenes;
    if (scenes.empty() && opt.sceneDir.empty() && !opt.scaling) throw UsageError(dataFolder.string() + ": no animations found");
  }
  scenes.insert(scenes.end(), sceneFiles.begin(), sceneFiles.end());
  if (b.twoLevelOnly) {  // the two-level part is the scene files' alone
    std::erase_if(scenes, [](const SceneSource& s) { return !anim::isSceneFile(s.input); });
    if (scenes.empty())
      throw UsageError("--two-level-only benches scene files (docs/scenes.md): give --scene-dir DIR or scene files");
  }
  if (opt.list) {
    for (const SceneSource& s : scenes) std::printf("%-16s %-9s %s\n", s.name.c_str(), s.kind.c_str(), s.input.c_str());
    for (const SkippedEntry& s : scan.skipped) std::printf("%-16s %-9s %s (%s)\n", "-", "skipped", s.path.c_str(), s.reason.c_str());
    return;
  }

  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) throw tsah::Failure(out.string() + ": cannot create the output folder");
  if (opt.scaling) return runScalingMode(opt, sub, scenes, log);
  // The two-level part optimizes each scene file with `tsah optimize` children of this program,
  // which resolve the scenes' data: paths from the same data folder and cache.
  std::error_code exeError;
  b.program = fs::read_symlink("/proc/self/exe", exeError).string();
  if (exeError) throw tsah::Failure("cannot find the tsah program (/proc/self/exe): " + exeError.message());
  if (!opt.data.empty()) ::setenv("TSAH_DATA_DIR", fs::absolute(opt.data).c_str(), 1);
  ::setenv("TSAH_CACHE_DIR", fs::absolute(cache).c_str(), 1);
  json results;
  results["tool"] = "tsah bench";
  results["command"] = commandLine();
  results["started"] = nowText();
  results["machine"] = machineJson(b.device == tsah::Device::Cuda);
  json versions = versionsJson();
  versions["gnuplot"] = gnuplotVersion();
  results["versions"] = versions;
  results["options"] = optionsJson(b);
  results["seed"] = b.seed;
  results["data"] = {{"folder", scanned ? dataFolder.string() : ""}, {"cache", cache.string()}};
  results["paper_source"] = kPaperSource;
  json notes = json::array();
  if (b.quick) notes.push_back("--quick: a smoke run with small images and few frames; not for comparison");
  if (b.traceFrames < 50 && !b.quick)
    notes.push_back("the runtime part (Table 2 and the Embree comparison) traced " + std::to_string(b.traceFrames) +
                    " frames per method (--trace-frames " + std::to_string(b.traceFrames) +
                    "), fewer than the default 50, uniform over each animation");
  for (const std::string& n : opt.notes) notes.push_back(n);
  results["notes"] = notes;
  results["scenes"] = json::array();
  results["failed"] = json::array();
  results["skipped"] = json::array();
  for (const SkippedEntry& s : scan.skipped) results["skipped"].push_back({{"path", s.path}, {"reason", s.reason}});

  const auto started = std::chrono::steady_clock::now();
  log("benchmarking " + std::to_string(scenes.size()) + " scene(s) on the " + std::string(tsah::name(b.device)) + " into " + out.string(), false);
  for (const SceneSource& scene : scenes) {
    const auto start = std::chrono::steady_clock::now();
    try {
      json j = benchScene(scene, b, out, [&](const std::string& m, bool detail) { log(m, detail); });
      j["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (const PaperScene* p = findPaperScene(scene.name, j["triangles"].get<uint32_t>(), false)) j["paper"] = paperJson(*p);
      results["scenes"].push_back(j);
    } catch (const NotAnAnimation& e) {
      results["skipped"].push_back({{"path", scene.input}, {"reason", e.what()}});
      log(scene.name + ": skipped: " + e.what(), false);
    } catch (const std::bad_alloc&) {
      results["failed"].push_back({{"path", scene.input}, {"reason", "out of memory"}});
      log(scene.name + ": failed: out of memory", false);
    } catch (const std::exception& e) {
      results["failed"].push_back({{"path", scene.input}, {"reason", e.what()}});
      log(scene.name + ": failed: " + e.what(), false);
    }
    results["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    writeReport(out, results);  // after every scene, so a long run can be read while it goes on
  }
  results["finished"] = nowText();
  makePlotsInto(results, out, log);
  writeReport(out, results);
  if (results["scenes"].empty())
    throw tsah::Failure("no scene could be benchmarked (see " + (out / "results.md").string() + ")");
  const std::string blurTable = motionBlurSummary(results["scenes"]);  // the motion-blur part's table, when run
  if (!blurTable.empty()) std::printf("%s", blurTable.c_str());
  std::printf("%s\n%s\n", (out / "results.md").c_str(), (out / "results.json").c_str());
}

}  // namespace

TSAH_REGISTER_COMMAND(80, [](CLI::App& app) {
  auto* sub = app.add_subcommand("bench", "The paper's Tables 1 and 2, Figures 3-6, segments and the Embree peer on "
                                          "real animations: results.json, results.md, plots");
  auto opt = std::make_shared<Options>();
  tsah::bench::BenchOptions& b = opt->bench;
  sub->add_option("SCENES", opt->scenes,
                  "Scene names of the data folder (see --list) or inputs (any form `tsah info` reads); default: every "
                  "animation in the data folder");
  sub->add_option("--data", opt->data,
                  "Data folder (default: $TSAH_DATA_DIR, else ../shared/data next to the source checkout)");
  tsah::cli::addChoice(*sub, "--device", b.device, "Where the runtime part runs: cpu, or cuda (the GPU runtime)",
                       {tsah::Device::Cpu, tsah::Device::Cuda});
  sub->add_option("--out", opt->out, "Output folder: results.json, results.md, plots/, images/")->capture_default_str();
  sub->add_option("--scene-dir", opt->sceneDir,
                  "Also bench every scene file (*.json, docs/scenes.md) of this folder, e.g. samples/scenes/bench; "
                  "their data: paths resolve against --data");
  sub->add_option("--cache", opt->cache, "Where archives of the data folder are unpacked (default: OUT/cache)");
  sub->add_flag("--quick", b.quick, "Smoke run: 10 evaluation frames, 3 traced frames of 192x144 (explicit options win)");
  sub->add_option("--seed", b.seed, "Seed of the optimizations and of the per-pixel random numbers")->capture_default_str();
  sub->add_option("--frames", b.frames, "Representative frames of every optimization")
      ->check(CLI::Range(1u, 1000u))
      ->capture_default_str();
  sub->add_option("--eval-frames", b.evalFrames, "Evaluation frames of the cost tables")
      ->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
  sub->add_option("--trace-frames", b.traceFrames, "Frames traced per runtime method")
      ->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
  sub->add_option("--width", b.width, "Image width")->check(CLI::Range(1u, 16384u))->capture_default_str();
  sub->add_option("--height", b.height, "Image height")->check(CLI::Range(1u, 16384u))->capture_default_str();
  sub->add_option("--ao", b.aoRays, "Ambient-occlusion rays per pixel")->check(CLI::Range(0u, 1024u))->capture_default_str();
  sub->add_option("--shadow", b.shadowRays, "Shadow rays per pixel")->check(CLI::Range(0u, 1024u))->capture_default_str();
  sub->add_flag("--ground", b.ground, "Add the analytic ground plane (the paper traces the meshes alone)");
  sub->add_option("--max-leaf", b.objective.maxLeafSize, "Largest leaf of every tree")->check(CLI::Range(1u, 256u))->capture_default_str();
  sub->add_option("--ct", b.objective.cost.ct, "Cost of traversing a node")->check(CLI::PositiveNumber)->capture_default_str();
  sub->add_option("--ci", b.objective.cost.ci, "Cost of intersecting a triangle")->check(CLI::PositiveNumber)->capture_default_str();
  sub->add_option("--segments", b.segments,
                  "K of the segmented T-SAH: K equal-time parts and the count mode with K trees (1: skip)")
      ->check(CLI::Range(1u, 64u))
      ->capture_default_str();
  sub->add_option("--budget", b.budget,
                  "Budget mode: the fewest trees keeping every evaluation frame within this factor of SAH-rebuild "
                  "(0: skip)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  sub->add_option("--threads", b.threads, "CPU worker threads (0: all cores)")->capture_default_str();
  sub->add_option("--devices", opt->devices,
                  "With --device cuda: all, or GPU indices such as 0,2: the GPU methods of Table 2 dealt to these "
                  "GPUs, each method's frames on one GPU (per-method figures as on one GPU, the run shorter)");
  sub->add_option("--optimizer", b.optimizer,
                  "Optimizer of SAH*, SAH-rebuild and T-SAH: sequential (the paper's), parallel (all cores) or "
                  "cuda (parallel reinsertion on the GPU)")
      ->check(CLI::IsMember({"sequential", "parallel", "cuda"}))
      ->capture_default_str();
  sub->add_flag("--no-embree", opt->noEmbree, "Skip the Embree peer");
  sub->add_flag("--embree-only", b.embreeOnly,
                "Only the T-SAH tree and the toolkit (bvh2/bvh4/bvh8) vs Embree comparison: no Tables 1 and 2, "
                "no convergence runs, no segments");
  tsah::cli::addChoice(*sub, "--layout", b.layout,
                       "Tree layout of Table 2: auto (the device's fastest: on the CPU the widest the processor's SIMD "
                  "kernels support, also the default of the Embree comparison), CPU bvh2, bvh4 or bvh8, cuda bvh2 "
                  "or cwbvh (compressed 8-wide: the refitted trees and the LBVH / HLBVH-SAH rebuilds, whose "
                  "conversion on the GPU counts in their update)",
                       {tsah::Layout::Auto, tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8, tsah::Layout::Cwbvh});
  opt->shutter.add(
      *sub,
      "Motion-blur part (CPU): the shutter's length as a fraction of the time between traced frames, 0 to 1 "
      "(default 0: no motion-blur part); the toolkit's refit at the shutter's keys against Embree's motion-blur BVH "
      "(built once, and rebuilt every frame) on the same rays at the same times",
      "centered: the shutter around each traced frame's time (default); open: starting at it");
  sub->add_flag("--motion-blur-only", b.motionBlurOnly,
                "Only the T-SAH tree and the motion-blur part (with --shutter): no Tables 1 and 2, convergence runs, "
                "segments or instant Embree comparison");
  sub->add_flag("--two-level-only", b.twoLevelOnly,
                "Only the two-level part of every scene file (--scene-dir or scene files given): flat tree, "
                "two-level structure and Embree instancing on the same rays; no Tables 1 and 2, segments or Embree peer");
  sub->add_flag("--two-level-gpu", opt->twoLevelGpu,
                "The two-level part also runs tsah_two_level_gpu_bench (next to tsah; CUDA build and a device) on "
                "its two trees: GpuTwoLevelRuntime against GpuRuntime over the flat tree, per-frame update and trace");
  sub->add_flag("--no-convergence", opt->noConvergence, "Skip the random and batch-sort optimizations of the convergence plot");
  sub->add_option("--note", opt->notes,
                  "A note for results.md (repeatable), e.g. what else ran on the machine; with --report-only it is "
                  "added to the finished run");
  sub->add_flag("--list", opt->list, "List the scenes found (and skipped) and exit");
  sub->add_flag("--scaling", opt->scaling,
                "Scaling mode: optimization time, peak memory and T-SAH cost against the triangle count, per "
                "optimizer (generated explode animations and the scenes): OUT/scaling.json, scaling.md, plots");
  sub->add_option("--scaling-sizes", opt->scalingOptions.sizes, "--scaling: triangle counts of the explode animations")
      ->check(CLI::Range(100u, 100000000u))
      ->delimiter(',')
      ->allow_extra_args(false)
      ->capture_default_str();
  sub->add_option("--scaling-optimizers", opt->scalingOptions.optimizers,
                  "--scaling: optimizers to compare (cuda: the GPU optimizer, added by default when a device is present)")
      ->check(CLI::IsMember({"sequential", "parallel", "cuda"}))
      ->delimiter(',')
      ->allow_extra_args(false)
      ->capture_default_str();
  sub->add_flag("--report-only", opt->reportOnly, "Only redo results.md and the plots from OUT/results.json");
  sub->callback([opt, sub] { run(*opt, sub); });
});
