// tsah trace ANIMATION BVH.tbvh: per frame interpolate, refit (or rebuild), recompute Woop triangles
// and trace primary, ambient-occlusion and shadow rays, on the CPU (tsah::CpuRuntime) or on the GPU
// (tsah::cuda::GpuRuntime); one PNG per frame and timings.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "bvh_info.hpp"
#include "camera_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "cli.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/camera_path.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/build/sah_builder.hpp"
#if TSAH_HAVE_CUDA
#include "tsah_cuda/device.hpp"
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#endif

namespace {

using tsah::cli::UsageError;

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

tsah::Vec3 parseVec3(const std::string& text, const std::string& option) {
  std::stringstream in(text);
  float v[3];
  char comma;
  if (!(in >> v[0] >> comma) || comma != ',' || !(in >> v[1] >> comma) || comma != ',' || !(in >> v[2]) ||
      !(in >> std::ws).eof())
    throw UsageError(option + " expects x,y,z (three comma-separated numbers), got '" + text + "'");
  for (float x : v)
    if (!std::isfinite(x)) throw UsageError(option + ": coordinates must be finite");
  return {v[0], v[1], v[2]};
}

struct TraceOptions {
  std::string input, bvh, device = "cpu", out = "trace", camera, eye, lookAt, up = "0,1,0", rebuild = "none";
  std::string layout = "auto", isa = "auto";  // tree layout (CPU or GPU) and the CPU's SIMD kernels
  uint32_t frames = 0, width = 1024, height = 768, ao = 8, shadow = 2, threads = 0, seed = 1;
  float fov = 45.0f, aoDistance = 0.0f, aoFraction = 0.1f;
  bool json = false, noImages = false, noGround = false;
};

// Per-frame rebuild baselines: sweep and binned SAH run on the CPU, LBVH and HLBVH-SAH on the GPU.
bool isCpuRebuild(const std::string& r) { return r == "sweep" || r == "binned"; }
bool isGpuRebuild(const std::string& r) { return r == "lbvh" || r == "hlbvh-sah"; }

void checkDeviceAndRebuild(const TraceOptions& opt) {
  if (opt.device == "cpu" && isGpuRebuild(opt.rebuild))
    throw UsageError("--rebuild " + opt.rebuild + " is a GPU rebuild: use it with --device cuda "
                     "(the CPU rebuilds are sweep and binned)");
  if (opt.device == "cuda" && isCpuRebuild(opt.rebuild))
    throw UsageError("--rebuild " + opt.rebuild + " is a CPU rebuild: use it with --device cpu "
                     "(the GPU rebuilds are lbvh and hlbvh-sah)");
  tsah::cli::checkLayoutForDevice(opt.layout, opt.device);
  if (opt.device != "cuda") return;
#if TSAH_HAVE_CUDA
  if (!tsah::cuda::deviceAvailable())
    throw UsageError("no CUDA device found (no GPU, no NVIDIA driver, or CUDA_VISIBLE_DEVICES hides them); "
                     "use --device cpu");
#else
  throw UsageError("the GPU runtime is not built in this version of tsah (configure with a CUDA compiler to "
                   "build it); use --device cpu");
#endif
}

// What one frame's update cost: interpolation, refit (with the Woop triangles) or rebuild.
struct FrameUpdate {
  double interpolateMs = 0.0, refitMs = 0.0, buildMs = 0.0, updateMs = 0.0;
};

// The runtime the per-frame loop drives: bring the traced tree to time t (refit or rebuild), then
// render the frame. The CPU times with the host's clock, the GPU with CUDA events (device time).
class FrameRuntime {
 public:
  virtual ~FrameRuntime() = default;
  // Starts what the first timed frame must not pay for (worker threads; allocations, CUDA graph
  // capture and module loading on the GPU).
  virtual void warmUp(double time, const tsah::Camera& camera, const tsah::SceneLighting& lighting,
                      const tsah::RenderSettings& settings) = 0;
  virtual FrameUpdate update(double time) = 0;
  // image == nullptr: the picture is not needed (--no-images).
  virtual tsah::RenderStats render(const tsah::Camera& camera, const tsah::SceneLighting& lighting,
                                   const tsah::RenderSettings& settings, tsah::Image* image) = 0;
  virtual uint32_t currentTree() const = 0;           // of a tree set: the one the last update refitted
  virtual std::string summary() const = 0;            // for the text output's first line
  virtual void describe(nlohmann::json& out) const = 0;  // "device" and what else identifies it
};

class CpuFrameRuntime final : public FrameRuntime {
 public:
  CpuFrameRuntime(const tsah::TreeSet& trees, const anim::Animation& animation, const tsah::CpuRuntime::Config& config,
                  tsah::CpuRuntime::TreeBuilder builder)
      : animation_(animation),
        runtime_(trees, {animation.indices().begin(), animation.indices().end()}, animation.vertexCount(), config),
        builder_(std::move(builder)),
        positions_(animation.positionsAt(animation.startTime())) {}

  void warmUp(double, const tsah::Camera&, const tsah::SceneLighting&, const tsah::RenderSettings&) override {
    runtime_.parallelFor(runtime_.threadCount() * 4, 1, [](std::size_t, std::size_t) {});
  }

  FrameUpdate update(double time) override {
    FrameUpdate u;
    const auto start = std::chrono::steady_clock::now();
    animation_.movingPositionsAt(time, positions_);  // the static vertices are in place since construction
    u.interpolateMs = msSince(start);
    if (builder_) {
      const auto t = runtime_.rebuild(positions_, builder_);
      u.buildMs = t.boxesMs + t.buildMs + t.flattenMs;
      u.refitMs = t.refitMs;
    } else {
      const auto s = std::chrono::steady_clock::now();
      runtime_.selectTreeAt(time);
      runtime_.update(positions_);
      u.refitMs = msSince(s);
    }
    u.updateMs = msSince(start);
    return u;
  }

  tsah::RenderStats render(const tsah::Camera& camera, const tsah::SceneLighting& lighting,
                           const tsah::RenderSettings& settings, tsah::Image* image) override {
    return tsah::renderFrame(runtime_, camera, lighting, settings, image ? *image : scratch_);
  }

  uint32_t currentTree() const override { return runtime_.currentTree(); }
  std::string summary() const override {
    const tsah::LayoutInfo& l = runtime_.layoutInfo();
    std::string s = std::to_string(runtime_.threadCount()) + " CPU threads, " + tsah::layoutName(l.layout);
    if (l.layout != tsah::CpuLayout::Bvh2) s += std::string(" (") + tsah::isaName(l.isa) + ")";
    char cost[96];
    std::snprintf(cost, sizeof cost, ", T-SAH cost %.2f (binary %.2f)", l.layoutCost, l.binaryCost);
    return s + cost;
  }
  void describe(nlohmann::json& out) const override {
    const tsah::LayoutInfo& l = runtime_.layoutInfo();
    out["device"] = "cpu";
    out["threads"] = runtime_.threadCount();
    out["timer"] = "host steady clock";
    out["layout"] = tsah::layoutName(l.layout);
    if (l.layout != tsah::CpuLayout::Bvh2) out["isa"] = tsah::isaName(l.isa);
    out["tree"] = {{"interior_nodes", l.interiorNodes}, {"leaves", l.leaves}, {"depth", l.depth},
                   {"tsah_cost", l.layoutCost}, {"binary_tsah_cost", l.binaryCost}};
  }

 private:
  const anim::Animation& animation_;
  tsah::CpuRuntime runtime_;
  tsah::CpuRuntime::TreeBuilder builder_;
  std::vector<float> positions_;
  tsah::Image scratch_;
};

tsah::CpuRuntime::TreeBuilder cpuRebuilder(const std::string& rebuild, const tsah::CostModel& cost, uint32_t maxLeaf) {
  if (rebuild == "binned") {
    tsah::BinnedSahBuilder::Config c;
    c.cost = cost;
    c.maxLeafSize = maxLeaf;
    return [c](std::span<const tsah::Aabb> boxes) { return tsah::BinnedSahBuilder(c).build(boxes); };
  }
  if (rebuild == "sweep") {
    tsah::SweepSahBuilder::Config s;
    s.cost = cost;
    tsah::LeafCollapser::Config l;
    l.cost = cost;
    l.maxLeafSize = maxLeaf;
    return [s, l](std::span<const tsah::Aabb> boxes) {
      return tsah::LeafCollapser(l).collapse(tsah::SweepSahBuilder(s).build(boxes));
    };
  }
  return {};
}

#if TSAH_HAVE_CUDA
class GpuFrameRuntime final : public FrameRuntime {
 public:
  GpuFrameRuntime(const tsah::TreeSet& trees, const anim::Animation& animation,
                  std::optional<tsah::cuda::RebuildOptions> rebuild, tsah::cuda::GpuRuntime::Config config)
      : runtime_(trees, animation, config), rebuild_(rebuild) {}

  void warmUp(double time, const tsah::Camera& camera, const tsah::SceneLighting& lighting,
              const tsah::RenderSettings& settings) override {
    update(time);
    tsah::cuda::renderFrameGpu(runtime_, camera, lighting, settings, nullptr);
  }

  FrameUpdate update(double time) override {
    FrameUpdate u;
    if (rebuild_) {
      const tsah::cuda::RebuildTimings t = runtime_.rebuildAt(time, *rebuild_);
      u = {t.interpolateMs, t.woopMs, t.buildMs() + t.wideMs, t.totalMs()};  // layout cwbvh: with the conversion
    } else {
      const tsah::cuda::UpdateTimings t = runtime_.updateAt(time);
      u = {t.interpolateMs, t.refitMs + t.woopMs, 0.0, t.totalMs()};
    }
    return u;
  }

  tsah::RenderStats render(const tsah::Camera& camera, const tsah::SceneLighting& lighting,
                           const tsah::RenderSettings& settings, tsah::Image* image) override {
    return tsah::cuda::renderFrameGpu(runtime_, camera, lighting, settings, image);
  }

  uint32_t currentTree() const override { return runtime_.currentTree(); }
  std::string summary() const override {
    return "GPU " + runtime_.device().name + ", " + tsah::cuda::treeLayoutName(runtime_.config().layout) + " layout";
  }
  void describe(nlohmann::json& out) const override {
    const tsah::cuda::DeviceInfo& d = runtime_.device();
    out["device"] = d.name;
    out["gpu"] = {{"name", d.name},
                  {"compute_capability", std::to_string(d.computeMajor) + "." + std::to_string(d.computeMinor)},
                  {"multiprocessors", d.multiprocessors},
                  {"memory_mib", d.globalMemoryBytes >> 20},
                  {"cuda_runtime", d.runtimeVersion},
                  {"cuda_driver", d.driverVersion}};
    out["timer"] = "CUDA events (device time)";
    out["layout"] = tsah::cuda::treeLayoutName(runtime_.config().layout);
  }

 private:
  tsah::cuda::GpuRuntime runtime_;
  std::optional<tsah::cuda::RebuildOptions> rebuild_;
};
#endif

std::unique_ptr<FrameRuntime> makeRuntime(const TraceOptions& opt, const tsah::TreeSet& trees,
                                          const tsah::BvhBuildInfo& info, const anim::Animation& a) {
  const tsah::CostModel cost = info.objective.cost;
  const uint32_t maxLeaf = std::max(1u, info.objective.maxLeafSize);
#if TSAH_HAVE_CUDA
  if (opt.device == "cuda") {
    std::optional<tsah::cuda::RebuildOptions> rebuild;
    if (isGpuRebuild(opt.rebuild)) {
      rebuild.emplace();
      rebuild->method = tsah::cuda::parseRebuildMethod(opt.rebuild);
      rebuild->maxLeafSize = maxLeaf;
      rebuild->cost = cost;
    }
    tsah::cuda::GpuRuntime::Config config;
    if (opt.layout != "auto") config.layout = tsah::cuda::parseTreeLayout(opt.layout);
    // The compressed layout holds leaves of at most 8 triangles (64 per node), as its refit path's
    // collapse does.
    if (rebuild && config.layout == tsah::cuda::TreeLayout::Cwbvh)
      rebuild->maxLeafSize = std::min(rebuild->maxLeafSize, tsah::kCwbvhMaxLeafTriangles);
    return std::make_unique<GpuFrameRuntime>(trees, a, rebuild, config);
  }
#endif
  tsah::CpuRuntime::Config config(opt.threads);
  config.layout = opt.layout == "auto" ? tsah::fastestLayout() : *tsah::parseLayout(opt.layout);
  if (opt.isa != "auto") config.isa = tsah::parseIsa(opt.isa);
  config.collapse = tsah::wideCollapseConfig(info.objective);
  return std::make_unique<CpuFrameRuntime>(trees, a, config, cpuRebuilder(opt.rebuild, cost, maxLeaf));
}

struct FrameResult {
  uint32_t frame = 0;
  double time = 0.0;
  uint32_t tree = 0;  // of a tree set: the tree of the frame's part
  FrameUpdate update;
  tsah::RenderStats render;
  double pngMs = 0.0;
  std::string image;
};

nlohmann::json raysJson(const tsah::RenderStats& s) {
  return {{"primary", s.primary.rays}, {"ao", s.ao.rays}, {"shadow", s.shadow.rays}, {"total", s.total().rays}};
}
nlohmann::json rateJson(const tsah::RenderStats& s) {
  return {{"primary", s.primary.mraysPerSecond()},
          {"ao", s.ao.mraysPerSecond()},
          {"shadow", s.shadow.mraysPerSecond()},
          {"total", s.total().mraysPerSecond()}};
}
nlohmann::json traceMsJson(const tsah::RenderStats& s) {
  return {{"primary", s.primary.ms}, {"ao", s.ao.ms}, {"shadow", s.shadow.ms}};
}

void runTrace(const TraceOptions& opt) {
  namespace fs = std::filesystem;
  checkDeviceAndRebuild(opt);
  if (opt.eye.empty() != opt.lookAt.empty()) throw UsageError("--eye and --look-at go together");
  if (!opt.camera.empty() && !opt.eye.empty()) throw UsageError("give either --camera or --eye/--look-at");
  if (!(opt.fov > 0.0f && opt.fov < 180.0f)) throw UsageError("--fov must be between 0 and 180 degrees");
  if (!(opt.aoFraction > 0.0f) || !std::isfinite(opt.aoFraction)) throw UsageError("--ao-fraction must be positive");
  if (opt.aoDistance < 0.0f || !std::isfinite(opt.aoDistance)) throw UsageError("--ao-distance must be positive");
  const tsah::Vec3 up = parseVec3(opt.up, "--up");
  if (!(tsah::dot(up, up) > 0.0f)) throw UsageError("--up must not be zero");

  // Inputs: the tree (or tree set: each frame refits the tree of its part) is validated completely
  // by the reader; then it must match the animation.
  const tsah::TreeSet trees = tsah::decodeTreeSetFile(tsah::readFile(opt.bvh), opt.bvh);
  const tsah::BvhBuildInfo& info = trees.builds.front();
  const anim::Animation a = tsah::cli::loadInput(opt.input);
  tsah::cli::checkTreeMatchesAnimation(info, opt.bvh, a, opt.input);
  const std::unique_ptr<FrameRuntime> rt = makeRuntime(opt, trees, info, a);

  const uint32_t frameCount = opt.frames ? opt.frames : std::min<uint32_t>(a.keyframeCount(), 50);
  const std::vector<double> times = a.uniformTimes(frameCount);

  // Camera: a file, the command line, the animation's own camera path, or fitted to the bounds
  // of all frames (so it does not move while the animation plays).
  const anim::Bounds ab = a.bounds();
  tsah::Aabb bounds;
  bounds.extend(tsah::Vec3{ab.min[0], ab.min[1], ab.min[2]});
  bounds.extend(tsah::Vec3{ab.max[0], ab.max[1], ab.max[2]});
  const float aspect = float(opt.width) / float(opt.height);
  std::vector<anim::CameraKey> path;
  std::string cameraSource;
  tsah::Camera fixedCamera;
  if (!opt.camera.empty()) {
    path = tsah::cli::loadCameraFile(opt.camera);
    cameraSource = opt.camera;
  } else if (!opt.eye.empty()) {
    fixedCamera = {parseVec3(opt.eye, "--eye"), parseVec3(opt.lookAt, "--look-at"), up, opt.fov};
    tsah::validateCamera(fixedCamera);
    cameraSource = "command line";
  } else if (!a.cameraPath().empty()) {
    path.assign(a.cameraPath().begin(), a.cameraPath().end());
    cameraSource = "animation camera path";
  } else {
    fixedCamera = tsah::fitCamera(bounds, up, opt.fov, aspect);
    cameraSource = "fitted to the animation bounds";
  }
  auto cameraAt = [&](double t) { return path.empty() ? fixedCamera : tsah::cameraAt(path, t); };
  tsah::SceneLighting lighting = tsah::fitLighting(bounds, cameraAt(times.front()), up, opt.aoFraction, !opt.noGround);
  if (opt.aoDistance > 0.0f) lighting.aoDistance = opt.aoDistance;

  if (!opt.noImages) {
    std::error_code ec;
    fs::create_directories(opt.out, ec);
    if (ec || !fs::is_directory(opt.out)) throw tsah::Failure(opt.out + ": cannot create the output folder");
  }

  tsah::RenderSettings settings;
  settings.width = opt.width;
  settings.height = opt.height;
  settings.aoSamples = opt.ao;
  settings.shadowSamples = opt.shadow;
  settings.seed = opt.seed;
  rt->warmUp(times.front(), cameraAt(times.front()), lighting, settings);

  const bool rebuilds = opt.rebuild != "none";
  const std::string mode =
      rebuilds ? "rebuild " + opt.rebuild + (isGpuRebuild(opt.rebuild) ? " (GPU)" : " (CPU)")
               : trees.size() > 1 ? "refit of the tree of each frame's part (" + std::to_string(trees.size()) + " trees)"
                                  : "refit";
  if (!opt.json)
    std::printf("%u frames, %ux%u, %u AO + %u shadow rays per pixel, %s, %s, camera %s\n", frameCount, opt.width,
                opt.height, opt.ao, opt.shadow, rt->summary().c_str(), mode.c_str(), cameraSource.c_str());
  tsah::Image image;
  std::vector<FrameResult> results;
  tsah::cli::Progress progress("tracing");
  for (uint32_t f = 0; f < frameCount; ++f) {
    progress.update(f, frameCount);
    FrameResult r;
    r.frame = f;
    r.time = times[f];
    r.update = rt->update(r.time);
    r.tree = rt->currentTree();
    settings.frame = f;
    r.render = rt->render(cameraAt(r.time), lighting, settings, opt.noImages ? nullptr : &image);
    if (!opt.noImages) {
      const auto s = std::chrono::steady_clock::now();
      char name[32];
      std::snprintf(name, sizeof name, "frame_%04u.png", f);
      r.image = (fs::path(opt.out) / name).string();
      tsah::savePng(r.image, image);
      r.pngMs = msSince(s);
    }
    results.push_back(r);
  }

  // Averages: times are means over frames, rates are total rays over total time per ray type.
  FrameResult avg;
  tsah::RenderStats sum;
  for (const FrameResult& r : results) {
    avg.update.interpolateMs += r.update.interpolateMs / frameCount;
    avg.update.refitMs += r.update.refitMs / frameCount;
    avg.update.buildMs += r.update.buildMs / frameCount;
    avg.update.updateMs += r.update.updateMs / frameCount;
    avg.render.shadeMs += r.render.shadeMs / frameCount;
    for (auto [total, part] : {std::pair{&sum.primary, &r.render.primary}, std::pair{&sum.ao, &r.render.ao},
                               std::pair{&sum.shadow, &r.render.shadow}}) {
      total->rays += part->rays;
      total->ms += part->ms;
    }
  }
  auto traceMs = [](const tsah::RenderStats& s) { return s.total().ms; };

  if (opt.json) {
    nlohmann::json out;
    rt->describe(out);
    out["animation"] = opt.input;
    out["bvh"] = opt.bvh;
    out["method"] = info.method;
    out["trees"] = trees.size();
    out["rebuild"] = opt.rebuild;
    out["width"] = opt.width;
    out["height"] = opt.height;
    out["ao_rays_per_pixel"] = opt.ao;
    out["shadow_rays_per_pixel"] = opt.shadow;
    out["ao_distance"] = lighting.aoDistance;
    out["ground"] = lighting.ground;
    out["camera"] = cameraSource;
    out["triangles"] = a.triangleCount();
    nlohmann::json frames = nlohmann::json::array();
    for (const FrameResult& r : results) {
      nlohmann::json j;
      j["frame"] = r.frame;
      j["time"] = r.time;
      if (!rebuilds) j["tree"] = r.tree;
      j["update_ms"] = r.update.updateMs;
      j["interpolate_ms"] = r.update.interpolateMs;
      j["refit_ms"] = r.update.refitMs;
      if (rebuilds) j["build_ms"] = r.update.buildMs;
      j["trace_ms"] = traceMs(r.render);
      j["trace_ms_by_type"] = traceMsJson(r.render);
      j["shade_ms"] = r.render.shadeMs;
      j["total_ms"] = r.update.updateMs + traceMs(r.render);
      j["rays"] = raysJson(r.render);
      j["mrays_per_s"] = rateJson(r.render);
      if (!r.image.empty()) j["image"] = r.image;
      frames.push_back(j);
    }
    out["frames"] = frames;
    nlohmann::json av;
    av["update_ms"] = avg.update.updateMs;
    av["interpolate_ms"] = avg.update.interpolateMs;
    av["refit_ms"] = avg.update.refitMs;
    if (rebuilds) av["build_ms"] = avg.update.buildMs;
    av["trace_ms"] = traceMs(sum) / frameCount;
    tsah::RenderStats perFrame = sum;
    for (auto* p : {&perFrame.primary, &perFrame.ao, &perFrame.shadow}) p->ms /= frameCount;
    av["trace_ms_by_type"] = traceMsJson(perFrame);
    av["shade_ms"] = avg.render.shadeMs;
    av["total_ms"] = avg.update.updateMs + traceMs(sum) / frameCount;
    av["mrays_per_s"] = rateJson(sum);
    out["average"] = av;
    std::printf("%s\n", out.dump().c_str());
    return;
  }
  std::printf("%5s %8s %10s %9s %9s %9s %9s %9s %9s\n", "frame", "time", "update_ms", "trace_ms", "total_ms",
              "MR/s prim", "MR/s ao", "MR/s shad", "MR/s all");
  auto row = [&](const char* label, const std::string& time, double update, const tsah::RenderStats& s,
                 double frames) {
    std::printf("%5s %8s %10.3f %9.3f %9.3f %9.2f %9.2f %9.2f %9.2f\n", label, time.c_str(), update,
                s.total().ms / frames, update + s.total().ms / frames, s.primary.mraysPerSecond(),
                s.ao.mraysPerSecond(), s.shadow.mraysPerSecond(), s.total().mraysPerSecond());
  };
  for (const FrameResult& r : results) {
    char time[32];
    std::snprintf(time, sizeof time, "%.3f", r.time);
    row(std::to_string(r.frame).c_str(), time, r.update.updateMs, r.render, 1.0);
  }
  row("avg", "-", avg.update.updateMs, sum, frameCount);
  std::printf("update = interpolate %.3f + %s %.3f ms per frame; shading %.3f ms (not in total)\n",
              avg.update.interpolateMs, rebuilds ? "rebuild" : "refit+Woop",
              avg.update.updateMs - avg.update.interpolateMs, avg.render.shadeMs);
  if (!opt.noImages) std::printf("images in %s/frame_NNNN.png\n", opt.out.c_str());
}

}  // namespace

TSAH_REGISTER_COMMAND(70, [](CLI::App& app) {
  auto* sub = app.add_subcommand(
      "trace", "Trace every frame with only a refit (or a rebuild): PNG per frame, update and ray-tracing times");
  auto opt = std::make_shared<TraceOptions>();
  sub->add_option("ANIMATION", opt->input, "The animation (any input `tsah info` reads)")->required();
  sub->add_option("BVH", opt->bvh, "Tree from `tsah optimize` (.tbvh) built for this animation")->required();
  sub->add_option("--device", opt->device, "cpu (default) or cuda (the GPU runtime, when built and a GPU is present)")
      ->check(CLI::IsMember({"cpu", "cuda"}));
  sub->add_option("--frames", opt->frames,
                  "Frames to trace, uniform over the animation's time range (default: one per keyframe, at most 50)");
  sub->add_option("--width", opt->width, "Image width (default 1024)")->check(CLI::Range(1u, 16384u));
  sub->add_option("--height", opt->height, "Image height (default 768)")->check(CLI::Range(1u, 16384u));
  sub->add_option("--ao", opt->ao, "Ambient-occlusion rays per pixel (default 8)")->check(CLI::Range(0u, 1024u));
  sub->add_option("--shadow", opt->shadow, "Shadow rays per pixel (default 2)")->check(CLI::Range(0u, 1024u));
  sub->add_option("--ao-distance", opt->aoDistance, "Maximum AO ray length (default: --ao-fraction of the scene diagonal)");
  sub->add_option("--ao-fraction", opt->aoFraction, "AO ray length as a fraction of the scene diagonal (default 0.1)");
  sub->add_option("--out", opt->out, "Folder for frame_NNNN.png (default ./trace)");
  sub->add_flag("--no-images", opt->noImages, "Do not write PNG files (timing runs)");
  sub->add_flag("--no-ground", opt->noGround, "No ground plane: only the animated mesh (as in the paper's runs)");
  sub->add_option("--rebuild", opt->rebuild,
                  "none: refit the given tree (default); otherwise build a new tree every frame (baseline): "
                  "sweep or binned SAH on the CPU (--device cpu), lbvh or hlbvh-sah on the GPU (--device cuda; "
                  "with --layout cwbvh each rebuilt tree is converted to the compressed 8-wide layout on the GPU, "
                  "and the conversion counts in the update)")
      ->check(CLI::IsMember({"none", "sweep", "binned", "lbvh", "hlbvh-sah"}));
  sub->add_option("--camera", opt->camera, "Camera JSON file: {eye, look_at, up, fov} or {keys: [{time, ...}]}");
  sub->add_option("--eye", opt->eye, "Camera position x,y,z (with --look-at)");
  sub->add_option("--look-at", opt->lookAt, "Point the camera looks at x,y,z");
  sub->add_option("--up", opt->up, "Scene up direction x,y,z (default 0,1,0)");
  sub->add_option("--fov", opt->fov, "Vertical field of view in degrees (default 45)");
  sub->add_option("--threads", opt->threads, "CPU worker threads (0: all cores)");
  sub->add_option("--layout", opt->layout,
                  "Tree layout: CPU bvh2 (the binary tree), bvh4 or bvh8 (wide trees collapsed from it at load "
                  "time); GPU bvh2 or cwbvh (compressed 8-wide, docs/cwbvh.md; for the refitted tree and the "
                  "--rebuild trees); default auto: on the CPU the widest "
                  "the processor's SIMD kernels support, on the GPU the runtime's default")
      ->check(CLI::IsMember({"auto", "bvh2", "bvh4", "bvh8", "cwbvh"}));
  sub->add_option("--isa", opt->isa, "CPU SIMD kernels of a wide layout: sse, avx2 or avx512 (default auto: the best)")
      ->check(CLI::IsMember({"auto", "sse", "avx2", "avx512"}));
  sub->add_option("--seed", opt->seed, "Seed of the per-pixel random numbers (default 1)");
  sub->add_flag("--json", opt->json, "Print one JSON object {device, frames: [...], average: {...}}");
  sub->callback([opt] { runTrace(*opt); });
});
