#pragma once
// The per-frame driver of `tsah trace` and `tsah bench`: bring the traced tree to a time (refit of
// the tree of the frame's part, or a rebuild) and render the frame with the renderer's workload, on
// the CPU (CpuRuntime + renderFrame, timed with the host's clock) or on the GPU (GpuRuntime +
// renderFrameGpu, timed with CUDA events). Also the one JSON description of the device.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/core/objective.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/image.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace tsah::cli {

// What one frame's update cost, in milliseconds: interpolation, refit with the Woop triangles (or,
// after a rebuild, the Woop pass), the rebuild itself (with the GPU's conversion to the compressed
// layout, also given alone as convertMs) and all of it.
struct FrameUpdate {
  double interpolateMs = 0.0, refitMs = 0.0, buildMs = 0.0, convertMs = 0.0, updateMs = 0.0;
  uint32_t keys = 1;  // the shutter's key times refitted (1: the instant)
};

// One rendered frame: the rays and milliseconds of each pass, and the whole frame (GPU: device time
// of every pass, the shading and the download; CPU: the ray passes).
struct FrameRender {
  RenderStats rays;
  double frameMs = 0.0;
};

// The per-frame rebuild baselines: sweep and binned SAH run on the CPU, LBVH and HLBVH-SAH on the GPU.
enum class Rebuild { None, Sweep, Binned, Lbvh, HlbvhSah };
// "none", "sweep", "binned", "lbvh", "hlbvh-sah"; parseRebuild throws tsah::ConfigError otherwise.
const char* rebuildName(Rebuild rebuild);
Rebuild parseRebuild(const std::string& name);
inline bool isGpuRebuild(Rebuild r) { return r == Rebuild::Lbvh || r == Rebuild::HlbvhSah; }
inline bool isCpuRebuild(Rebuild r) { return r == Rebuild::Sweep || r == Rebuild::Binned; }
// Throws tsah::cli::UsageError for a rebuild of the other device.
void checkRebuildForDevice(Rebuild rebuild, Device device);

class FrameRuntime {
 public:
  virtual ~FrameRuntime() = default;
  // Does what no timed frame must pay for: wakes the worker threads (CPU); brings every tree of the
  // set to a time inside its part and renders once (GPU: allocations, module loading, the capture of
  // each tree's CUDA graph).
  virtual void warmUp(double firstTime, const std::function<Camera(double)>& cameraAt, const SceneLighting& lighting,
                      const RenderSettings& settings) = 0;
  virtual FrameUpdate update(double time) = 0;
  // image == nullptr: the picture is not kept.
  virtual FrameRender render(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings,
                             Image* image) = 0;
  virtual uint32_t currentTree() const = 0;  // of a tree set: the one the last update refitted
  virtual std::string summary() const = 0;   // one line: the device and the layout
  // "device", "timer", "layout" and what else identifies the runtime (threads and tree for the CPU,
  // "gpu": deviceJson() for the GPU).
  virtual void describe(nlohmann::json& out) const = 0;
};

// What a runtime traces and how it updates.
struct FrameRuntimeOptions {
  Device device = Device::Cpu;
  int gpu = 0;                       // the GPU of Device::Cuda
  Layout layout = Layout::Auto;      // Auto: the device's fastest
  std::optional<SimdIsa> isa;        // CPU wide layouts: the kernels (default: the best the processor runs)
  // CPU wide layouts: how the tree holds each frame's triangles (default: the runtime's, Woop; of a
  // two-level scene, its poses' form, vertex packets).
  std::optional<TriangleForm> triangles;
  unsigned threads = 0;              // CPU worker threads (0: all cores)
  Rebuild rebuild = Rebuild::None;   // a new tree every frame instead of the refit
  // The tree's objective: cT, cI and the largest leaf of the rebuilds; with k, the collapse into the
  // wide layouts (CPU bvh4/bvh8, GPU cwbvh).
  Objective objective;
  // Motion blur (bvh2, CPU or GPU): each frame refitted over its shutter (tsah::shutterInterval
  // with frameInterval, the time between traced frames) and traced at each pixel's time.
  Shutter shutter;
  double frameInterval = 0.0;
};

// The runtime of `trees` (each refitted in its part of the animation, or trees.trees[0] the first
// tree of a rebuild every frame) for `animation`. Throws tsah::ConfigError for a GPU request in a
// build without CUDA, tsah::Failure on a machine without a GPU, UsageError for a rebuild of the
// other device.
std::unique_ptr<FrameRuntime> makeFrameRuntime(const TreeSet& trees, const anim::Animation& animation,
                                               const FrameRuntimeOptions& options);

// GPU `index` as JSON: name, compute_capability, multiprocessors,
// memory_mib, driver_version, runtime_version; null without CUDA or without a device.
nlohmann::json deviceJson(int index = 0);
bool gpuAvailable();
// Before a GPU runtime is made: throws tsah::ConfigError in a build without CUDA, tsah::Failure on a
// machine without a usable GPU.
void requireGpuRuntime();

}  // namespace tsah::cli
