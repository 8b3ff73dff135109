#include "frame_runtime.hpp"

#include <algorithm>
#include <chrono>
#include <span>

#include "cli.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/optimize/leaf_collapser.hpp"

#if TSAH_HAVE_CUDA
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#endif

namespace tsah::cli {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

constexpr std::pair<Rebuild, const char*> kRebuildNames[] = {{Rebuild::None, "none"},
                                                             {Rebuild::Sweep, "sweep"},
                                                             {Rebuild::Binned, "binned"},
                                                             {Rebuild::Lbvh, "lbvh"},
                                                             {Rebuild::HlbvhSah, "hlbvh-sah"}};

// The CPU rebuilds: binned SAH with its own leaf rule, or the sweep SAH collapsed like the T-SAH tree.
CpuRuntime::TreeBuilder cpuRebuilder(Rebuild rebuild, const Objective& objective) {
  const uint32_t maxLeaf = std::max(1u, objective.maxLeafSize);
  if (rebuild == Rebuild::Binned) {
    BinnedSahBuilder::Config c;
    c.cost = objective.cost;
    c.maxLeafSize = maxLeaf;
    return [c](std::span<const Aabb> boxes) { return BinnedSahBuilder(c).build(boxes); };
  }
  if (rebuild == Rebuild::Sweep) {
    SweepSahBuilder::Config s;
    s.cost = objective.cost;
    const LeafCollapser::Config l{0, objective.cost, maxLeaf};  // one frame: k = 0
    return [s, l](std::span<const Aabb> boxes) { return LeafCollapser(l).collapse(SweepSahBuilder(s).build(boxes)); };
  }
  return {};
}

class CpuFrameRuntime final : public FrameRuntime {
 public:
  CpuFrameRuntime(const TreeSet& trees, const anim::Animation& animation, const CpuRuntime::Config& config,
                  CpuRuntime::TreeBuilder builder, Shutter shutter, double frameInterval)
      : shutter_(shutter),
        frameInterval_(frameInterval),
        animation_(animation),
        runtime_(trees, {animation.indices().begin(), animation.indices().end()}, animation.vertexCount(), config),
        builder_(std::move(builder)),
        positions_(animation.positionsAt(animation.startTime())) {}  // the static vertices, once

  void warmUp(double, const std::function<Camera(double)>&, const SceneLighting&, const RenderSettings&) override {
    runtime_.parallelFor(runtime_.threadCount() * 4, 1, [](std::size_t, std::size_t) {});
  }

  FrameUpdate update(double time) override {
    FrameUpdate u;
    const auto start = std::chrono::steady_clock::now();
    if (shutter_.fraction > 0.0) {
      // Interpolation and the refit at every key (tsah::updateShutter does both).
      const auto [open, close] = shutterInterval(animation_, time, frameInterval_, shutter_);
      updateShutter(runtime_, animation_, open, close);  // a tree set: each ray's tree by its time
      u.refitMs = msSince(start);
      u.keys = runtime_.blurred() ? runtime_.shutterKeyCount() : 1u;
    } else if (builder_) {
      interpolate(time, u);
      const CpuRuntime::RebuildTimings t = runtime_.rebuild(positions_, builder_);
      u.buildMs = t.boxesMs + t.buildMs + t.flattenMs;
      u.refitMs = t.refitMs;
    } else {
      interpolate(time, u);
      const auto s = std::chrono::steady_clock::now();
      runtime_.selectTreeAt(time);  // a tree set: the tree of this frame's part
      runtime_.update(positions_);
      u.refitMs = msSince(s);
    }
    u.updateMs = msSince(start);
    return u;
  }

  FrameRender render(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings,
                     Image* image) override {
    FrameRender r;
    r.rays = renderFrame(runtime_, camera, lighting, settings, image ? *image : scratch_);
    r.frameMs = r.rays.total().ms;
    return r;
  }

  uint32_t currentTree() const override { return runtime_.currentTree(); }

  std::string summary() const override {
    const LayoutInfo& l = runtime_.layoutInfo();
    std::string s = std::to_string(runtime_.threadCount()) + " CPU threads, " + name(l.layout);
    if (l.layout != Layout::Bvh2) s += std::string(" (") + name(l.isa) + ")";
    if (l.triangles == TriangleForm::Vertices) s += ", triangles as vertex packets";
    char cost[96];
    std::snprintf(cost, sizeof cost, ", T-SAH cost %.2f (binary %.2f)", l.layoutCost, l.binaryCost);
    return s + cost;
  }

  void describe(nlohmann::json& out) const override {
    const LayoutInfo& l = runtime_.layoutInfo();
    out["device"] = "cpu";
    out["threads"] = runtime_.threadCount();
    out["timer"] = "host steady clock";
    out["layout"] = name(l.layout);
    if (l.layout != Layout::Bvh2) out["isa"] = name(l.isa);
    out["triangle_form"] = name(l.triangles);
    out["tree"] = {{"interior_nodes", l.interiorNodes}, {"leaves", l.leaves}, {"depth", l.depth},
                   {"tsah_cost", l.layoutCost}, {"binary_tsah_cost", l.binaryCost}};
  }

 private:
  void interpolate(double time, FrameUpdate& u) {
    const auto start = std::chrono::steady_clock::now();
    animation_.movingPositionsAt(time, positions_);
    u.interpolateMs = msSince(start);
  }

  Shutter shutter_;
  double frameInterval_;
  const anim::Animation& animation_;
  CpuRuntime runtime_;
  CpuRuntime::TreeBuilder builder_;
  std::vector<float> positions_;
  Image scratch_;
};

#if TSAH_HAVE_CUDA
class GpuFrameRuntime final : public FrameRuntime {
 public:
  GpuFrameRuntime(const TreeSet& trees, const anim::Animation& animation,
                  std::optional<cuda::RebuildOptions> rebuild, const cuda::GpuRuntime::Config& config,
                  Shutter shutter, double frameInterval)
      : runtime_(trees, animation, config),
        ranges_(trees.ranges),
        rebuild_(rebuild),
        animation_(animation),
        shutter_(shutter),
        frameInterval_(frameInterval) {}

  // The runtime's GPU current while it is released.
  ~GpuFrameRuntime() override { cuda::useDevice(runtime_.config().device); }

  // Each call first makes the runtime's GPU the calling thread's (the threads of --devices).
  void warmUp(double firstTime, const std::function<Camera(double)>& cameraAt, const SceneLighting& lighting,
              const RenderSettings& settings) override {
    cuda::useDevice(runtime_.config().device);
    // The first update of each tree captures its CUDA graph: a time inside each tree's part reaches
    // every tree (a rebuild has one graph).
    const std::size_t trees = rebuild_ ? 1 : ranges_.size();
    for (std::size_t s = 0; s < trees; ++s) {
      const double t = s == 0 ? firstTime : switchTime(ranges_, uint32_t(s - 1));
      update(t);
      cuda::renderFrameGpu(runtime_, cameraAt(t), lighting, settings, nullptr, nullptr);
    }
  }

  FrameUpdate update(double time) override {
    cuda::useDevice(runtime_.config().device);
    if (rebuild_) {
      const cuda::RebuildTimings t = runtime_.rebuildAt(time, *rebuild_);
      return {t.interpolateMs, t.woopMs, t.buildMs() + t.wideMs, t.wideMs, t.totalMs()};  // cwbvh: with the conversion
    }
    if (shutter_.fraction > 0.0) {
      // Interpolation and the refit at every key, on the device (updateShutterAt does both).
      const auto [open, close] = shutterInterval(animation_, time, frameInterval_, shutter_);
      const cuda::UpdateTimings t = runtime_.updateShutterAt(open, close);
      return {t.interpolateMs, t.refitMs + t.woopMs, 0.0, 0.0, t.totalMs(), std::max(1u, runtime_.shutterKeyCount())};
    }
    const cuda::UpdateTimings t = runtime_.updateAt(time);
    return {t.interpolateMs, t.refitMs + t.woopMs, 0.0, 0.0, t.totalMs()};
  }

  FrameRender render(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings,
                     Image* image) override {
    cuda::useDevice(runtime_.config().device);
    cuda::GpuRenderTimings timings;
    FrameRender r;
    r.rays = cuda::renderFrameGpu(runtime_, camera, lighting, settings, image, &timings);
    r.frameMs = timings.totalMs;
    return r;
  }

  uint32_t currentTree() const override { return runtime_.currentTree(); }

  std::string summary() const override {
    return "GPU " + runtime_.device().name + ", " + tsah::name(runtime_.config().layout) + " layout";
  }

  void describe(nlohmann::json& out) const override {
    out["device"] = runtime_.device().name;
    out["gpu"] = deviceJson(runtime_.config().device);
    out["timer"] = "CUDA events (device time)";
    out["layout"] = tsah::name(runtime_.config().layout);
  }

 private:
  cuda::GpuRuntime runtime_;
  std::vector<TimeRange> ranges_;
  std::optional<cuda::RebuildOptions> rebuild_;
  const anim::Animation& animation_;
  Shutter shutter_;
  double frameInterval_;
};

std::unique_ptr<FrameRuntime> makeGpuFrameRuntime(const TreeSet& trees, const anim::Animation& animation,
                                                  const FrameRuntimeOptions& options) {
  cuda::GpuRuntime::Config config;
  config.device = options.gpu;
  config.layout = gpuLayout(options.layout);
  // The cwbvh collapse of trees without build infos (a set read from a file brings each tree's own).
  config.wideObjective = options.objective;
  std::optional<cuda::RebuildOptions> rebuild;
  if (options.rebuild != Rebuild::None) {
    rebuild.emplace();
    rebuild->method = options.rebuild == Rebuild::Lbvh ? cuda::RebuildMethod::Lbvh : cuda::RebuildMethod::HlbvhSah;
    rebuild->cost = options.objective.cost;
    rebuild->maxLeafSize = std::max(1u, options.objective.maxLeafSize);
    // The compressed layout holds leaves of at most 8 triangles (64 per node), as its refit path's
    // collapse does.
    if (config.layout == tsah::Layout::Cwbvh)
      rebuild->maxLeafSize = std::min(rebuild->maxLeafSize, kCwbvhMaxLeafTriangles);
  }
  return std::make_unique<GpuFrameRuntime>(trees, animation, rebuild, config, options.shutter, options.frameInterval);
}
#endif

}  // namespace

const char* rebuildName(Rebuild rebuild) {
  for (const auto& [value, text] : kRebuildNames)
    if (value == rebuild) return text;
  return "?";
}

Rebuild parseRebuild(const std::string& text) {
  for (const auto& [value, name] : kRebuildNames)
    if (text == name) return value;
  throw ConfigError("unknown rebuild '" + text + "' (expected none, sweep, binned, lbvh or hlbvh-sah)");
}

void checkRebuildForDevice(Rebuild rebuild, Device device) {
  const bool gpu = device == Device::Cuda;
  if (gpu ? isCpuRebuild(rebuild) : isGpuRebuild(rebuild))
    throw UsageError(std::string("--rebuild ") + rebuildName(rebuild) + " is a " + (gpu ? "CPU" : "GPU") +
                     " rebuild: use it with --device " +
                     (gpu ? "cpu (the GPU rebuilds are lbvh and hlbvh-sah)" : "cuda (the CPU rebuilds are sweep and binned)"));
}

std::unique_ptr<FrameRuntime> makeFrameRuntime(const TreeSet& trees, const anim::Animation& animation,
                                               const FrameRuntimeOptions& options) {
  checkRebuildForDevice(options.rebuild, options.device);
  if (options.device == Device::Cuda) {
    requireGpuRuntime();
#if TSAH_HAVE_CUDA
    return makeGpuFrameRuntime(trees, animation, options);
#endif
  }
  CpuRuntime::Config config(options.threads);
  config.layout = options.layout == Layout::Auto ? fastestLayout(options.isa) : options.layout;
  config.isa = options.isa;
  if (options.triangles) config.triangles = *options.triangles;
  config.collapse = wideCollapseConfig(options.objective);
  // The frames come from the animation, whose static vertices stay at rest: refit what moves.
  if (!animation.allMoving())
    config.movingVertices.emplace(animation.movingVertices().begin(), animation.movingVertices().end());
  return std::make_unique<CpuFrameRuntime>(trees, animation, config, cpuRebuilder(options.rebuild, options.objective),
                                           options.shutter, options.frameInterval);
}

#if TSAH_HAVE_CUDA
bool gpuAvailable() { return cuda::deviceAvailable(); }

void requireGpuRuntime() {
  if (!cuda::deviceAvailable())
    throw Failure("no CUDA device found (no GPU, no NVIDIA driver, or CUDA_VISIBLE_DEVICES hides them); "
                  "use --device cpu");
}

nlohmann::json deviceJson(int index) {
  if (!cuda::deviceAvailable()) return nullptr;
  const cuda::DeviceInfo d = cuda::describeDevice(index);
  return {{"name", d.name},
          {"compute_capability", std::to_string(d.computeMajor) + "." + std::to_string(d.computeMinor)},
          {"multiprocessors", d.multiprocessors},
          {"memory_mib", double(d.globalMemoryBytes) / (1024.0 * 1024.0)},
          {"driver_version", d.driverVersion},
          {"runtime_version", d.runtimeVersion}};
}
#else
bool gpuAvailable() { return false; }

void requireGpuRuntime() {
  throw ConfigError("the GPU runtime is not built in this version of tsah (configure with a CUDA compiler to "
                    "build it); use --device cpu");
}
nlohmann::json deviceJson(int) { return nullptr; }
#endif

}  // namespace tsah::cli
