#pragma once
// `tsah bench`: the paper's evaluation on one scene at a time, as one JSON object per scene (the
// layout is documented in docs/bench.md; report.hpp turns it into results.md and the plots).
//
// Per scene:
//   table1       SAH-rebuild, SAH*, SAH0, T-SAH k=0/2/4 (tsah::compareMethods): build time, average
//                and maximum cost over the evaluation frames, the cost of every evaluation frame
//   convergence  the T-SAH (k=0) optimization with Metropolis-Hastings, random and batch-sort
//                node selection: cost after every batch against time (the paper's Figure 3)
//   segments     K T-SAH trees for K equal-time parts (the paper's BART Museum*), K trees with split
//                points chosen by the count mode, and the budget mode, versus one tree
//   runtime      per-frame update + trace with the renderer's workload: refit of SAH0, SAH*, T-SAH
//                and the K segment trees versus per-frame rebuilds (CPU: sweep and binned SAH;
//                GPU: LBVH and HLBVH-SAH)
//   embree       CPU only: the toolkit's T-SAH refit against Embree rebuilds and refit on the same rays
//   motion_blur  CPU only, with a shutter: the toolkit's blurred frames against Embree's motion-blur
//                BVH (built once, and rebuilt every frame) on the same rays at the same times
//   two_level    CPU only, scene files: the flat tree against the two-level structure and Embree
//                instancing on the same rays (two_level_bench.hpp)
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "bench/data_scan.hpp"
#include "bench/runtime_bench.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/core/objective.hpp"
#include "tsah/base/error.hpp"
#include "tsah/pipeline.hpp"

namespace tsah::bench {

struct BenchOptions {
  Device device = Device::Cpu;  // where the runtime part runs
  bool quick = false;           // smoke run: the caller sets the smaller sizes below
  uint64_t seed = 1;            // optimizer seed (and per-pixel random numbers)
  uint32_t frames = 5;          // representative frames
  uint32_t evalFrames = 50;     // evaluation frames of the cost tables
  uint32_t traceFrames = 50;    // frames traced per runtime method
  uint32_t width = 1024, height = 768;
  uint32_t aoRays = 8, shadowRays = 2;
  bool ground = false;          // the analytic ground plane (the paper traces the mesh only)
  Objective objective;          // cT, cI and the largest leaf of every tree (k: each method's own)
  uint32_t segments = 3;        // K of the equal-time parts and of the count mode (1: skip)
  double budget = 1.05;         // budget mode: factor of SAH-rebuild's cost per evaluation frame (0: skip)
  unsigned threads = 0;         // CPU threads (0: all cores)
  std::vector<int> devices;     // --device cuda: the GPUs the runtime methods are dealt to (empty: GPU 0)
  std::string optimizer = "sequential";  // optimizer of SAH*, SAH-rebuild and T-SAH: sequential | parallel | cuda
  bool embree = true;           // run the Embree peer when built with it (CPU device only)
  bool embreeOnly = false;      // only the T-SAH tree and the toolkit-vs-Embree comparison (no Tables 1/2)
  Shutter shutter;              // fraction > 0: the motion-blur part (CPU, the toolkit vs Embree's motion blur)
  bool motionBlurOnly = false;  // only the T-SAH tree and the motion-blur part
  Layout layout = Layout::Auto;  // tree layout of the runtime part: Auto (the device's fastest); CPU bvh2,
                                 // bvh4, bvh8; cuda bvh2 or cwbvh
  bool convergence = true;      // run the three node selections for the convergence plot
  double fps = 0.0;             // import: sampling rate of continuous animations (0: the file's own)
  std::string clip;             // import: the animation clip of a multi-clip model (empty: the first)
  std::function<std::string(const std::string&)> resolveDataPath;  // import: scenes' "data:" paths
  bool twoLevelOnly = false;    // scene files: only the two-level part (no Tables 1/2, Embree peer, segments)
  std::string program;          // the tsah executable the two-level part's optimizations run as
  std::string gpuTwoLevelProgram;  // set: the two-level part also runs this tsah_two_level_gpu_bench
};

// Progress: `detail` messages are frequent (optimizer batches) and may be thinned out by the caller.
using BenchProgress = std::function<void(const std::string& message, bool detail)>;

// Thrown by benchScene for an input that is not an animation (one keyframe): the scene is skipped.
class NotAnAnimation : public tsah::DataError {
 public:
  using tsah::DataError::DataError;
};

// Runs the benchmark on one scene. The traced picture of the T-SAH refit (middle frame, half size
// when large) goes to outDir/images/<scene>.png. Throws tsah::FileError for unreadable inputs,
// NotAnAnimation (a tsah::DataError) for a static one.
nlohmann::json benchScene(const SceneSource& scene, const BenchOptions& options, const std::filesystem::path& outDir,
                          const BenchProgress& progress);

// What a runtime part traces of animation `a` at `times`: the camera (its camera path, else fitted
// to its bounds over all frames), the light, the image size and rays per pixel, threads, layout
// (Auto: the device's fastest) and the wide layouts' collapse, from the options.
RuntimeSetup runtimeSetupFor(const anim::Animation& a, std::vector<double> times, const BenchOptions& options,
                             std::function<void(const std::string&)> progress);

// The machine (CPU model, cores, memory, OS; the GPU when withGpu), the versions (tsah, compiler,
// Embree, CUDA) and the options, for results.json.
nlohmann::json machineJson(bool withGpu);
nlohmann::json versionsJson();
nlohmann::json optionsJson(const BenchOptions& options);

// The label the report prints for a cost-table method id (rebuild -> SAH-rebuild, tsah2 -> T-SAH k=2).
std::string methodLabel(const std::string& id);

}  // namespace tsah::bench
