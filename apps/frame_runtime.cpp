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
                  CpuRuntime::TreeBuilder builder)
      : animation_(animation),
        runtime_(trees, {animation.indices().begin(), animation.indices().end()}, animation.vertexCount(), config),
        builder_(std::move(builder)),
        positions_(animation.positionsAt(animation.startTime())) {}  // the static vertices, once

  void warmUp(double, const std::function<Camera(double)>&, const SceneLighting&, const RenderSettings&) override {
    runtime_.parallelFor(runtime_.threadCount() * 4, 1, [](std::size_t, std::size_t) {});
  }

  FrameUpdate update(double time) override {
    FrameUpdate u;
    const auto start = std::chrono::steady_clock::now();
    animation_.movingPositionsAt(time, positions_);
    u.interpolateMs = msSince(start);
    if (builder_) {
      const CpuRuntime::RebuildTimings t = runtime_.rebuild(positions_, builder_);
      u.buildMs = t.boxesMs + t.buildMs + t.flattenMs;
      u.refitMs = t.refitMs;
    } else {
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
    out["tree"] = {{"interior_nodes", l.interiorNodes}, {"leaves", l.leaves}, {"depth", l.depth},
                   {"tsah_cost", l.layoutCost}, {"binary_tsah_cost", l.binaryCost}};
  }

 private:
  const anim::Animation& animation_;
  CpuRuntime runtime_;
  CpuRuntime::TreeBuilder builder_;
  std::vector<float> positions_;
  Image scratch_;
};

#if TSAH_HAVE_CUDA
// The rebuild options of a GPU rebuild baseline in `layout`.
std::optional<cuda::RebuildOptions> gpuRebuildOptions(Rebuild rebuild, const Objective& objective, Layout layout) {
  if (rebuild == Rebuild::None) return std::nullopt;
  cuda::RebuildOptions o;
  o.method = rebuild == Rebuild::Lbvh ? cuda::RebuildMethod::Lbvh : cuda::RebuildMethod::HlbvhSah;
  o.cost = objective.cost;
  o.maxLeafSize = std::max(1u, objective.maxLeafSize);
  // The compressed layout holds leaves of at most 8 triangles (64 per node), as its refit path's
  // collapse does.
  if (layout == Layout::Cwbvh) o.maxLeafSize = std::min(o.maxLeafSize, kCwbvhMaxLeafTriangles);
  return o;
}

class GpuFrameRuntime final : public FrameRuntime {
 public:
  // config.layout Auto: a runtime in each GPU layout; warmUp measures both on the first frame and
  // keeps the faster (until then the binary one is used).
  GpuFrameRuntime(const TreeSet& trees, const anim::Animation& animation, Rebuild rebuild, const Objective& objective,
                  const cuda::GpuRuntime::Config& config)
      : ranges_(trees.ranges) {
    const bool measure = config.layout == Layout::Auto;
    for (const Layout layout : measure ? std::vector{Layout::Bvh2, Layout::Cwbvh} : std::vector{config.layout}) {
      cuda::GpuRuntime::Config c = config;
      c.layout = layout;
      candidates_.push_back({std::make_unique<cuda::GpuRuntime>(trees, animation, c),
                             gpuRebuildOptions(rebuild, objective, layout), 0.0});
    }
  }

  void warmUp(double firstTime, const std::function<Camera(double)>& cameraAt, const SceneLighting& lighting,
              const RenderSettings& settings) override {
    for (std::size_t i = 0; i < candidates_.size(); ++i) {
      current_ = i;
      warmUpCurrent(firstTime, cameraAt, lighting, settings);
    }
    if (candidates_.size() == 1) return;
    // Which layout traces a scene faster depends on the scene and the view (the compressed one wins
    // on small characters, the binary one on some large BART scenes), so --layout auto measures it:
    // the first frame's update and render, best of kAutoRuns, in each layout; the faster is kept and
    // the other runtime freed.
    std::size_t best = 0;
    for (std::size_t i = 0; i < candidates_.size(); ++i) {
      current_ = i;
      double ms = 0.0;
      for (int run = 0; run < kAutoRuns; ++run) {
        const double total = update(firstTime).updateMs + render(cameraAt(firstTime), lighting, settings, nullptr).frameMs;
        ms = run == 0 ? total : std::min(ms, total);
      }
      candidates_[i].autoMs = ms;
      if (ms < candidates_[best].autoMs) best = i;
    }
    for (const Candidate& c : candidates_) autoChoice_[tsah::name(c.runtime->config().layout)] = c.autoMs;
    Candidate kept = std::move(candidates_[best]);
    candidates_.clear();
    candidates_.push_back(std::move(kept));
    current_ = 0;
  }

  FrameUpdate update(double time) override {
    Candidate& c = candidates_[current_];
    if (c.rebuild) {
      const cuda::RebuildTimings t = c.runtime->rebuildAt(time, *c.rebuild);
      return {t.interpolateMs, t.woopMs, t.buildMs() + t.wideMs, t.wideMs, t.totalMs()};  // cwbvh: with the conversion
    }
    const cuda::UpdateTimings t = c.runtime->updateAt(time);
    return {t.interpolateMs, t.refitMs + t.woopMs, 0.0, 0.0, t.totalMs()};
  }

  FrameRender render(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings,
                     Image* image) override {
    cuda::GpuRenderTimings timings;
    FrameRender r;
    r.rays = cuda::renderFrameGpu(runtime(), camera, lighting, settings, image, &timings);
    r.frameMs = timings.totalMs;
    return r;
  }

  uint32_t currentTree() const override { return runtime().currentTree(); }

  std::string summary() const override {
    std::string s = "GPU " + runtime().device().name + ", " + tsah::name(runtime().config().layout) + " layout";
    if (!autoChoice_.empty()) {
      char why[96];
      std::snprintf(why, sizeof why, " (auto: first frame bvh2 %.3f ms, cwbvh %.3f ms)",
                    autoChoice_["bvh2"].get<double>(), autoChoice_["cwbvh"].get<double>());
      s += why;
    }
    return s;
  }

  void describe(nlohmann::json& out) const override {
    out["device"] = runtime().device().name;
    out["gpu"] = deviceJson();
    out["timer"] = "CUDA events (device time)";
    out["layout"] = tsah::name(runtime().config().layout);
    // --layout auto: the first frame's update + render in each layout (best of kAutoRuns), ms.
    if (!autoChoice_.empty()) out["layout_auto_ms"] = autoChoice_;
  }

 private:
  static constexpr int kAutoRuns = 3;

  struct Candidate {
    std::unique_ptr<cuda::GpuRuntime> runtime;
    std::optional<cuda::RebuildOptions> rebuild;
    double autoMs;
  };

  cuda::GpuRuntime& runtime() const { return *candidates_[current_].runtime; }

  // The first update of each tree captures its CUDA graph: a time inside each tree's part reaches
  // every tree (a rebuild has one graph).
  void warmUpCurrent(double firstTime, const std::function<Camera(double)>& cameraAt, const SceneLighting& lighting,
                     const RenderSettings& settings) {
    const std::size_t trees = candidates_[current_].rebuild ? 1 : ranges_.size();
    for (std::size_t s = 0; s < trees; ++s) {
      const double t = s == 0 ? firstTime : switchTime(ranges_, uint32_t(s - 1));
      update(t);
      cuda::renderFrameGpu(runtime(), cameraAt(t), lighting, settings, nullptr, nullptr);
    }
  }

  std::vector<TimeRange> ranges_;
  std::vector<Candidate> candidates_;  // one, or with --layout auto both GPU layouts until warmUp
  std::size_t current_ = 0;
  nlohmann::json autoChoice_ = nlohmann::json::object();
};

std::unique_ptr<FrameRuntime> makeGpuFrameRuntime(const TreeSet& trees, const anim::Animation& animation,
                                                  const FrameRuntimeOptions& options) {
  if (!cuda::deviceAvailable())
    throw Failure("no CUDA device found (no GPU, no NVIDIA driver, or CUDA_VISIBLE_DEVICES hides them); "
                  "use --device cpu");
  cuda::GpuRuntime::Config config;
  config.layout = options.layout;  // Auto: measured on the first frame (GpuFrameRuntime::warmUp)
  // The cwbvh collapse of trees without build infos (a set read from a file brings each tree's own).
  config.wideObjective = options.objective;
  return std::make_unique<GpuFrameRuntime>(trees, animation, options.rebuild, options.objective, config);
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
#if TSAH_HAVE_CUDA
    return makeGpuFrameRuntime(trees, animation, options);
#else
    throw ConfigError("the GPU runtime is not built in this version of tsah (configure with a CUDA compiler to "
                      "build it); use --device cpu");
#endif
  }
  CpuRuntime::Config config(options.threads);
  config.layout = options.layout == Layout::Auto ? fastestLayout(options.isa) : options.layout;
  config.isa = options.isa;
  config.collapse = wideCollapseConfig(options.objective);
  return std::make_unique<CpuFrameRuntime>(trees, animation, config, cpuRebuilder(options.rebuild, options.objective));
}

#if TSAH_HAVE_CUDA
bool gpuAvailable() { return cuda::deviceAvailable(); }

nlohmann::json deviceJson() {
  if (!cuda::deviceAvailable()) return nullptr;
  const cuda::DeviceInfo d = cuda::describeDevice(0);
  return {{"name", d.name},
          {"compute_capability", std::to_string(d.computeMajor) + "." + std::to_string(d.computeMinor)},
          {"multiprocessors", d.multiprocessors},
          {"memory_mib", double(d.globalMemoryBytes) / (1024.0 * 1024.0)},
          {"driver_version", d.driverVersion},
          {"runtime_version", d.runtimeVersion}};
}
#else
bool gpuAvailable() { return false; }
nlohmann::json deviceJson() { return nullptr; }
#endif

}  // namespace tsah::cli
