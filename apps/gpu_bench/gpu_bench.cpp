// tsah_gpu_bench: the paper's Table 2 on the GPU, as one JSON object on stdout.
//
//   tsah_gpu_bench (--input FILE | --generate KIND:TRIANGLES:FRAMES)
//                  [--tree NAME=FILE.tbvh]... [--sah0] [--rebuild lbvh,hlbvh-sah|none]
//                  [--frames 50] [--width 1024] [--height 768] [--ao 8] [--shadow 2]
//                  [--traversal simple|persistent|both] [--layout bvh2,cwbvh] [--no-graphs] [--no-render] [--cpu-compare]
//                  [--image-dir DIR] [--builder sweep|binned] [--ground]
//                  [--shutter S [--shutter-mode centered|open]]
//
// For every tree (from .tbvh files, or SAH0 built here: sweep SAH on the first frame, collapsed to
// at most 8 triangles per leaf) and every GPU rebuild method, over `frames` times spread uniformly
// over the animation: per-frame update ms (interpolation + refit + Woop; for rebuilds interpolation
// + build + collapse + Woop, and the bare build without collapse and Woop), trace MRays/s of the
// primary, ambient-occlusion and shadow passes, and the total ms of the frame. Timings are CUDA
// events (device time); summaries give mean, median, min and max.
//
// --shutter S (layout bvh2): every refit frame is also drawn motion-blurred in the same runtime,
// refitted at the keys of its shutter (GpuRuntime::updateShutterAt over tsah::shutterInterval, S
// of the time between timed frames) and traced at each pixel's time; each refit method then gives
// "blurred" (its update, trace and frame figures, the keys, the bytes of the blurred geometry
// against the instant one) and "blurred_over_instant" (the ratios of the mean times).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/load.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/camera_path.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah_cuda/device.hpp"
#include "frame_runtime.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace {

using nlohmann::json;
namespace tc = tsah::cuda;

struct Options {
  std::string input, generate;
  std::vector<std::string> trees;
  bool sah0 = false;
  std::string rebuild = "lbvh,hlbvh-sah";
  uint32_t frames = 50, width = 1024, height = 768, ao = 8, shadow = 2;
  std::string traversal = "simple";
  std::string layout = "bvh2,cwbvh";  // layouts of the refitted trees, comma separated
  bool noRender = false, cpuCompare = false, noGraphs = false, noFuse = false, fullRefit = false;
  bool ground = false;  // the analytic ground plane (off: the meshes alone, as tsah bench and the paper)
  std::vector<float> wideCost;  // cwbvh collapse: cT, cI instead of the tree's objective's (empty: the tree's)
  uint32_t wideLeaf = 0;        // cwbvh collapse: largest leaf instead of the tree's objective's (0: the tree's)
  std::string imageDir;
  std::string builder = "sweep";
  uint32_t wideMerge = tsah::kCwbvhDefaultMergeTriangles;  // RebuildOptions::wideMergeTriangles
  double shutter = 0.0;                   // motion blur: fraction of the time between timed frames
  std::string shutterMode = "centered";   // centered | open
};

json summary(std::vector<double> v) {
  if (v.empty()) return json::object();
  std::sort(v.begin(), v.end());
  double sum = 0.0;
  for (double x : v) sum += x;
  const std::size_t n = v.size();
  const double median = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  return {{"mean", sum / double(n)}, {"median", median}, {"min", v.front()}, {"max", v.back()}};
}

double seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

anim::Animation loadAnimation(const Options& opt, json& info) {
  if (!opt.generate.empty()) {
    // KIND:TRIANGLES:FRAMES
    std::stringstream ss(opt.generate);
    std::string kind, tris, frames;
    std::getline(ss, kind, ':');
    std::getline(ss, tris, ':');
    std::getline(ss, frames, ':');
    anim::GeneratorOptions g;
    try {
      g.triangles = uint32_t(std::stoul(tris));
      g.frames = uint32_t(std::stoul(frames));
    } catch (const std::exception&) {
      throw tsah::ConfigError("--generate expects KIND:TRIANGLES:FRAMES, got '" + opt.generate + "'");
    }
    info["generated"] = opt.generate;
    return anim::generate(anim::parseGeneratorKind(kind), g);
  }
  info["file"] = opt.input;
  return anim::load(opt.input);
}

tsah::FlatBvh buildSah0(const anim::Animation& a, const std::string& builder) {
  std::vector<tsah::Aabb> boxes(a.triangleCount());
  tsah::triangleBoxes(a.indices(), a.keyframe(0), boxes);
  tsah::Bvh bvh;
  if (builder == "binned") {
    tsah::BinnedSahBuilder::Config c;
    c.maxLeafSize = 8;
    bvh = tsah::BinnedSahBuilder(c).build(boxes);
  } else {
    tsah::LeafCollapser::Config c;
    c.maxLeafSize = 8;
    bvh = tsah::LeafCollapser(c).collapse(tsah::SweepSahBuilder().build(boxes));
  }
  return tsah::flattenBvh(bvh);
}

// A tree to refit, and the objective of its 8-wide collapse (a file's own; SAH0: the default one).
struct Tree {
  std::string name;
  tsah::FlatBvh flat;
  tsah::Objective objective;
};

struct Scene {
  std::function<tsah::Camera(double)> camera;  // the animation's camera path, else fitted to its bounds
  tsah::SceneLighting lighting;
  tsah::RenderSettings settings;
};

// Accumulates one method's per-frame figures.
struct FrameSeries {
  std::vector<double> update, interpolate, refit, woop, build, bareBuild, render, total;
  std::vector<double> primary, ao, shadow, all;  // MRays/s per frame
  uint64_t rays[3] = {0, 0, 0};
  double traceMs[3] = {0, 0, 0};

  // After a frame's update: renders it (unless noRender) and records the rays and the frame's total.
  template <class Scene>
  void finishFrame(tc::GpuRuntime& rt, const Scene& scene, tsah::RenderSettings& settings, uint32_t frame, double time,
                   double updateMs, bool noRender) {
    if (noRender) {
      total.push_back(updateMs);
      return;
    }
    settings.frame = frame;
    tc::GpuRenderTimings g;
    addRender(tc::renderFrameGpu(rt, scene.camera(time), scene.lighting, settings, nullptr, &g), g, updateMs);
  }

  void addRender(const tsah::RenderStats& s, const tc::GpuRenderTimings& g, double updateMs) {
    primary.push_back(s.primary.mraysPerSecond());
    ao.push_back(s.ao.mraysPerSecond());
    shadow.push_back(s.shadow.mraysPerSecond());
    all.push_back(s.total().mraysPerSecond());
    const tsah::RayPassStats passes[3] = {s.primary, s.ao, s.shadow};
    for (int i = 0; i < 3; ++i) {
      rays[i] += passes[i].rays;
      traceMs[i] += passes[i].ms;
    }
    render.push_back(g.totalMs);
    total.push_back(updateMs + g.totalMs);
  }

  json traceJson() const {
    json j;
    const char* names[3] = {"primary", "ao", "shadow"};
    uint64_t allRays = 0;
    double allMs = 0.0;
    for (int i = 0; i < 3; ++i) {
      j[names[i]] = {{"rays_per_frame", rays[i] / std::max<std::size_t>(1, primary.size())},
                     {"mrays_per_s", traceMs[i] > 0 ? double(rays[i]) / (traceMs[i] * 1e3) : 0.0},
                     {"ms_per_frame", traceMs[i] / double(std::max<std::size_t>(1, primary.size()))}};
      allRays += rays[i];
      allMs += traceMs[i];
    }
    j["primary"]["per_frame_mrays_per_s"] = summary(primary);
    j["ao"]["per_frame_mrays_per_s"] = summary(ao);
    j["shadow"]["per_frame_mrays_per_s"] = summary(shadow);
    j["all"] = {{"mrays_per_s", allMs > 0 ? double(allRays) / (allMs * 1e3) : 0.0},
                {"ms_per_frame", allMs / double(std::max<std::size_t>(1, primary.size()))}};
    return j;
  }
};

// The cwbvh collapse follows the tree's objective, with the costs and leaf size of the command line.
tc::GpuRuntime::Config runtimeConfig(const Options& opt, bool persistent, tsah::Layout layout,
                                     tsah::Objective objective) {
  tc::GpuRuntime::Config c{0, persistent, !opt.noGraphs, layout, !opt.noFuse};
  c.skipStaticSubtrees = !opt.fullRefit;
  if (!opt.wideCost.empty()) objective.cost = {opt.wideCost[0], opt.wideCost[1]};
  if (opt.wideLeaf != 0) objective.maxLeafSize = opt.wideLeaf;
  c.wideObjective = objective;
  return c;
}

// The motion-blurred frames of a refit run (--shutter): the shutter of each frame and its figures.
struct BlurredFrames {
  tsah::Shutter shutter;
  double interval = 0.0;  // between timed frames
  FrameSeries series;
  std::vector<double> keys;
  tc::GpuRuntime::FrameBytes bytes;

  // The frame at `time` refitted over its shutter and rendered.
  void frame(tc::GpuRuntime& rt, const anim::Animation& a, const Scene& scene, tsah::RenderSettings& settings,
             uint32_t f, double time, bool noRender) {
    const auto [open, close] = tsah::shutterInterval(a, time, interval, shutter);
    const tc::UpdateTimings u = rt.updateShutterAt(open, close);
    series.update.push_back(u.totalMs());
    series.interpolate.push_back(u.interpolateMs);
    series.refit.push_back(u.refitMs + u.woopMs);
    keys.push_back(std::max(1u, rt.shutterKeyCount()));
    if (rt.blurred()) bytes = rt.frameBytes();
    series.finishFrame(rt, scene, settings, f, time, u.totalMs(), noRender);
  }

  // "blurred" and "blurred_over_instant" of the run's JSON.
  void report(json& j, const FrameSeries& instant, bool noRender) const {
    json b;
    b["shutter"] = {{"fraction", shutter.fraction},
                    {"mode", shutter.mode == tsah::Shutter::Mode::Open ? "open" : "centered"},
                    {"interval", interval}};
    b["keys"] = summary(keys);
    b["update_ms"] = summary(series.update);
    b["interpolate_ms"] = summary(series.interpolate);
    b["refit_ms"] = summary(series.refit);
    if (!noRender) {
      b["trace"] = series.traceJson();
      b["render_ms"] = summary(series.render);
    }
    b["total_ms"] = summary(series.total);
    b["bytes"] = {{"instant", bytes.instant},
                  {"blurred", bytes.blurred},
                  {"blurred_over_instant", bytes.instant ? double(bytes.blurred) / double(bytes.instant) : 0.0}};
    b["per_frame"] = {{"keys", keys}, {"update_ms", series.update}, {"total_ms", series.total}};
    j["blurred"] = b;
    auto ratio = [](const std::vector<double>& blurred, const std::vector<double>& base) {
      const double m = base.empty() ? 0.0 : summary(base)["mean"].get<double>();
      return m > 0.0 ? summary(blurred)["mean"].get<double>() / m : 0.0;
    };
    json r = {{"update", ratio(series.update, instant.update)}, {"total", ratio(series.total, instant.total)}};
    if (!noRender) {
      double blurredTrace = 0.0, instantTrace = 0.0;
      for (int i = 0; i < 3; ++i) {
        blurredTrace += series.traceMs[i];
        instantTrace += instant.traceMs[i];
      }
      r["trace"] = instantTrace > 0.0 ? blurredTrace / instantTrace : 0.0;
      r["render"] = ratio(series.render, instant.render);
    }
    j["blurred_over_instant"] = r;
  }
};

json runRefit(const Tree& t, const anim::Animation& a, const std::vector<double>& times, const Scene& scene,
              const Options& opt, bool persistent, tsah::Layout layout) {
  const tsah::FlatBvh& tree = t.flat;
  const auto setupStart = std::chrono::steady_clock::now();
  tc::GpuRuntime rt(tree, a, runtimeConfig(opt, persistent, layout, t.objective));
  const double setupSeconds = seconds(setupStart);
  const double mtris = double(a.triangleCount()) / 1e6;
  tsah::RenderSettings settings = scene.settings;
  std::optional<BlurredFrames> blur;
  if (opt.shutter > 0.0) {
    blur.emplace();
    blur->shutter.fraction = opt.shutter;
    blur->shutter.mode = opt.shutterMode == "open" ? tsah::Shutter::Mode::Open : tsah::Shutter::Mode::Centered;
    blur->interval = times[1] - times[0];
    // Warm-up of the blurred path too: the key refits replay the update graph, the render its kernels.
    BlurredFrames warm = *blur;
    warm.frame(rt, a, scene, settings, 0, times.front(), opt.noRender);
  }
  // Warm-up: module load, allocations, first-touch of the ray buffers.
  rt.updateAt(times.front());
  if (!opt.noRender) tc::renderFrameGpu(rt, scene.camera(times.front()), scene.lighting, settings, nullptr);

  FrameSeries s;
  for (uint32_t f = 0; f < times.size(); ++f) {
    if (blur) blur->frame(rt, a, scene, settings, f, times[f], opt.noRender);  // then the instant frame
    const tc::UpdateTimings u = rt.updateAt(times[f]);
    s.update.push_back(u.totalMs());
    s.interpolate.push_back(u.interpolateMs);
    s.refit.push_back(u.refitMs);
    s.woop.push_back(u.woopMs);
    s.finishFrame(rt, scene, settings, f, times[f], u.totalMs(), opt.noRender);
  }
  json j;
  j["name"] = t.name;
  j["kind"] = "refit";
  j["layout"] = tsah::name(layout);
  j["setup_seconds"] = setupSeconds;  // upload (and for cwbvh the 8-wide collapse + layout on the host)
  j["traversal"] = persistent ? "persistent" : "simple";
  if (layout == tsah::Layout::Cwbvh) {
    const tsah::Objective& o = rt.config().wideObjective;
    j["wide_collapse"] = {{"k", o.k},
                          {"ct", o.cost.ct},
                          {"ci", o.cost.ci},
                          {"max_leaf", std::min(o.maxLeafSize, tsah::kCwbvhMaxLeafTriangles)}};
  }
  j["tree"] = {{"interior_nodes", tree.interiorCount}, {"leaves", tree.leafCount}, {"depth", tree.depth}};
  j["update_ms"] = summary(s.update);
  j["update_ms_per_million_triangles"] = summary([&] {
    std::vector<double> v;
    for (double x : s.update) v.push_back(x / mtris);
    return v;
  }());
  j["interpolate_ms"] = summary(s.interpolate);
  j["refit_ms"] = summary(s.refit);
  j["woop_ms"] = summary(s.woop);
  if (!opt.noRender) j["trace"] = s.traceJson();
  j["total_ms"] = summary(s.total);
  j["per_frame"] = {{"update_ms", s.update}, {"total_ms", s.total}, {"ao_mrays_per_s", s.ao}};
  if (blur) blur->report(j, s, opt.noRender);
  return j;
}

// Layout cwbvh: every rebuilt tree is converted to the compressed 8-wide layout on the device; the
// conversion (phases_ms.wide) counts in the build and the update, as the binary Woop pass does.
json runRebuild(tc::RebuildMethod method, const Tree& tree, const anim::Animation& a,
                const std::vector<double>& times, const Scene& scene, const Options& opt, bool persistent,
                tsah::Layout layout) {
  tc::GpuRuntime rt(tree.flat, a, runtimeConfig(opt, persistent, layout, tree.objective));
  const double mtris = double(a.triangleCount()) / 1e6;
  tsah::RenderSettings settings = scene.settings;
  tc::RebuildOptions bare;
  bare.method = method;
  bare.collapse = false;
  bare.woop = false;
  bare.wideMergeTriangles = opt.wideMerge;
  tc::RebuildOptions full;
  full.method = method;
  full.wideMergeTriangles = opt.wideMerge;
  rt.rebuildAt(times.front(), bare);  // warm-up (allocations, CUB, module load)
  rt.rebuildAt(times.front(), full);
  if (!opt.noRender) tc::renderFrameGpu(rt, scene.camera(times.front()), scene.lighting, settings, nullptr);

  FrameSeries s;
  std::vector<double> morton, sort, hierarchy, top, bottomUp, wide, clusters, leaves, depth, wideNodes, wideLevels,
      ratio;
  for (uint32_t f = 0; f < times.size(); ++f) {
    const tc::RebuildTimings b = rt.rebuildAt(times[f], bare);
    s.bareBuild.push_back(b.buildMs());
    const tc::RebuildTimings t = rt.rebuildAt(times[f], full);
    s.build.push_back(t.buildMs() + t.wideMs + t.woopMs);
    ratio.push_back((t.buildMs() + t.wideMs + t.woopMs) / b.buildMs());
    s.update.push_back(t.totalMs());
    s.interpolate.push_back(t.interpolateMs);
    morton.push_back(t.mortonMs);
    sort.push_back(t.sortMs);
    hierarchy.push_back(t.hierarchyMs);
    top.push_back(t.topMs);
    bottomUp.push_back(t.bottomUpMs);
    wide.push_back(t.wideMs);
    wideNodes.push_back(t.wideNodes);
    wideLevels.push_back(t.wideLevels);
    s.woop.push_back(t.woopMs);
    clusters.push_back(t.clusters);
    leaves.push_back(t.leaves);
    depth.push_back(t.depth);
    s.finishFrame(rt, scene, settings, f, times[f], t.totalMs(), opt.noRender);
  }
  json j;
  j["name"] = tc::rebuildMethodName(method);
  j["kind"] = "rebuild";
  j["layout"] = tsah::name(layout);
  j["traversal"] = persistent ? "persistent" : "simple";
  j["bare_build_ms"] = summary(s.bareBuild);
  j["build_collapse_woop_ms"] = summary(s.build);
  j["collapse_woop_over_bare"] = summary(ratio);
  j["bare_build_ms_per_million_triangles"] = summary([&] {
    std::vector<double> v;
    for (double x : s.bareBuild) v.push_back(x / mtris);
    return v;
  }());
  j["phases_ms"] = {{"morton", summary(morton)},       {"sort", summary(sort)},
                    {"hierarchy", summary(hierarchy)}, {"cluster_tree", summary(top)},
                    {"bottom_up", summary(bottomUp)},  {"wide", summary(wide)},
                    {"woop", summary(s.woop)}};
  j["update_ms"] = summary(s.update);
  j["interpolate_ms"] = summary(s.interpolate);
  j["tree"] = {{"leaves", summary(leaves)}, {"depth", summary(depth)}};
  if (method == tc::RebuildMethod::HlbvhSah) j["tree"]["clusters"] = summary(clusters);
  if (layout == tsah::Layout::Cwbvh) {
    j["tree"]["wide_nodes"] = summary(wideNodes);
    j["tree"]["wide_levels"] = summary(wideLevels);
    j["wide_merge_triangles"] = opt.wideMerge;
  }
  if (!opt.noRender) j["trace"] = s.traceJson();
  j["total_ms"] = summary(s.total);
  j["per_frame"] = {{"update_ms", s.update}, {"bare_build_ms", s.bareBuild}, {"total_ms", s.total}};
  return j;
}

// One frame on the CPU renderer and on the GPU: how far apart the images are.
json compareWithCpu(const Tree& tree, const anim::Animation& a, double t, const Scene& scene, const Options& opt,
                    tsah::Layout layout) {
  tsah::CpuRuntime cpu(tree.flat, {a.indices().begin(), a.indices().end()}, a.vertexCount());
  tc::GpuRuntime gpu(tree.flat, a, runtimeConfig(opt, false, layout, tree.objective));
  cpu.update(a.positionsAt(t));
  gpu.updateAt(t);
  tsah::Image cpuImage, gpuImage;
  const auto start = std::chrono::steady_clock::now();
  const tsah::RenderStats cs = tsah::renderFrame(cpu, scene.camera(t), scene.lighting, scene.settings, cpuImage);
  const double cpuSeconds = seconds(start);
  const tsah::RenderStats gs = tc::renderFrameGpu(gpu, scene.camera(t), scene.lighting, scene.settings, gpuImage);
  const tsah::ImageDifference d = tsah::compareImages(cpuImage, gpuImage, 16);
  if (!opt.imageDir.empty()) {
    std::filesystem::create_directories(opt.imageDir);
    tsah::savePng(opt.imageDir + "/cpu.png", cpuImage);  // the same for every layout
    tsah::savePng(opt.imageDir + "/gpu-" + tsah::name(layout) + ".png", gpuImage);
  }
  return {{"layout", tsah::name(layout)},
          {"mean_abs", d.meanAbs},
          {"max_abs", d.maxAbs},
          {"fraction_above_16", d.fractionAbove},
          {"cpu_threads", cpu.threadCount()},
          {"cpu_seconds", cpuSeconds},
          {"cpu_mrays_per_s", cs.total().mraysPerSecond()},
          {"rays_cpu", {cs.primary.rays, cs.ao.rays, cs.shadow.rays}},
          {"rays_gpu", {gs.primary.rays, gs.ao.rays, gs.shadow.rays}}};
}

// --shutter's combinations, before the device is looked for.
void checkShutter(const Options& opt) {
  if (opt.shutter == 0.0) return;
  if (opt.frames < 2)
    throw tsah::ConfigError("--shutter needs at least two frames (it is a fraction of the time between them)");
  std::stringstream ss(opt.layout);
  for (std::string l; std::getline(ss, l, ',');)
    if (tsah::parse<tsah::Layout>(l) != tsah::Layout::Bvh2)
      throw tsah::ConfigError("--shutter: motion blur traces the bvh2 layout on the GPU (give --layout bvh2)");
}

void run(const Options& opt) {
  if (opt.input.empty() == opt.generate.empty()) throw tsah::ConfigError("give exactly one of --input and --generate");
  checkShutter(opt);
  if (!tc::deviceAvailable()) throw tsah::Failure("no CUDA device");
  json out;
  out["device"] = tsah::cli::deviceJson();

  json input;
  auto start = std::chrono::steady_clock::now();
  const anim::Animation a = loadAnimation(opt, input);
  input["load_seconds"] = seconds(start);
  input["triangles"] = a.triangleCount();
  input["vertices"] = a.vertexCount();
  input["keyframes"] = a.keyframeCount();
  out["input"] = input;

  const uint32_t frames = std::max<uint32_t>(1, opt.frames);
  const std::vector<double> times = a.uniformTimes(frames);
  Scene scene;
  scene.settings.width = opt.width;
  scene.settings.height = opt.height;
  scene.settings.aoSamples = opt.ao;
  scene.settings.shadowSamples = opt.shadow;
  const anim::Bounds ab = a.bounds();
  tsah::Aabb bounds;
  bounds.extend(tsah::Vec3{ab.min[0], ab.min[1], ab.min[2]});
  bounds.extend(tsah::Vec3{ab.max[0], ab.max[1], ab.max[2]});
  const tsah::Camera fitted = tsah::fitCamera(bounds, {0, 1, 0}, 45.0f, float(opt.width) / float(opt.height));
  std::vector<anim::CameraKey> cameraKeys(a.cameraPath().begin(), a.cameraPath().end());
  scene.camera = [cameraKeys, fitted](double t) { return cameraKeys.empty() ? fitted : tsah::cameraAt(cameraKeys, t); };
  scene.lighting = tsah::fitLighting(bounds, scene.camera(times.front()), {0, 1, 0}, 0.1f, opt.ground);
  out["settings"] = {{"frames", frames},       {"width", opt.width},   {"height", opt.height},
                     {"ao_samples", opt.ao},   {"shadow_samples", opt.shadow},
                     {"traversal", opt.traversal}, {"render", !opt.noRender}, {"graphs", !opt.noGraphs},
                     {"skip_static_subtrees", !opt.fullRefit},
                     {"fused_passes", !opt.noFuse}, {"ground", opt.ground}, {"shutter", opt.shutter},
                     {"camera", a.cameraPath().empty() ? "fitted to the animation bounds" : "the animation's camera path"}};

  // Trees: files, then SAH0 built here.
  std::vector<Tree> trees;
  for (const std::string& spec : opt.trees) {
    const auto eq = spec.find('=');
    const std::string name = eq == std::string::npos ? spec : spec.substr(0, eq);
    const std::string path = eq == std::string::npos ? spec : spec.substr(eq + 1);
    tsah::BvhBuildInfo info;
    tsah::FlatBvh flat = tsah::decodeFlatBvhFile(tsah::readFile(path), path, &info);
    trees.push_back({name, std::move(flat), info.objective});
    if (info.topologyHash != 0 && info.topologyHash != tsah::topologyHash(a.indices()))
      throw tsah::DataError(path + ": the tree was built for another animation (topology hash differs)");
  }
  json builds = json::object();
  if (opt.sah0 || trees.empty()) {
    start = std::chrono::steady_clock::now();
    trees.push_back({"sah0", buildSah0(a, opt.builder), tsah::Objective{}});
    builds["sah0"] = {{"builder", opt.builder + " + collapse(8)"}, {"seconds", seconds(start)}};
  }
  out["cpu_builds"] = builds;

  std::vector<bool> modes;
  if (opt.traversal == "persistent" || opt.traversal == "both") modes.push_back(true);
  if (opt.traversal == "simple" || opt.traversal == "both") modes.push_back(false);
  if (modes.empty()) throw tsah::ConfigError("--traversal must be persistent, simple or both");

  std::vector<tsah::Layout> layouts;
  {
    std::stringstream ss(opt.layout);
    std::string l;
    while (std::getline(ss, l, ',')) layouts.push_back(tsah::parse<tsah::Layout>(l));
  }
  if (layouts.empty()) throw tsah::ConfigError("--layout needs bvh2, cwbvh or both");

  json methods = json::array();
  for (tsah::Layout layout : layouts)
    for (bool persistent : modes) {
      for (const Tree& tree : trees) methods.push_back(runRefit(tree, a, times, scene, opt, persistent, layout));
    }
  if (opt.rebuild != "none") {
    std::stringstream ss(opt.rebuild);
    std::string m;
    while (std::getline(ss, m, ','))
      for (tsah::Layout layout : layouts)
        for (bool persistent : modes) {
          if (layout == tsah::Layout::Cwbvh && persistent) continue;  // the wide kernel is one thread per ray
          methods.push_back(
              runRebuild(tc::parseRebuildMethod(m), trees.front(), a, times, scene, opt, persistent, layout));
        }
  }
  out["methods"] = methods;
  if (opt.cpuCompare) {
    out["cpu_compare"] = json::array();
    for (tsah::Layout layout : layouts)
      out["cpu_compare"].push_back(compareWithCpu(trees.front(), a, times.front(), scene, opt, layout));
  }
  std::cout << out.dump(1) << std::endl;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tsah_gpu_bench: GPU update, rebuild and trace figures as one JSON object"};
  Options opt;
  app.add_option("--input", opt.input, "Animation file (.tanim or anything tsah reads)");
  app.add_option("--generate", opt.generate, "Generated animation KIND:TRIANGLES:FRAMES (explode, wave, swap)");
  app.add_option("--tree", opt.trees, "NAME=FILE.tbvh, a tree to refit (repeatable)");
  app.add_flag("--sah0", opt.sah0, "Also build SAH0 here (the default when no --tree is given)");
  app.add_option("--builder", opt.builder, "SAH0 builder: sweep (+ leaf collapse) or binned")
      ->check(CLI::IsMember({"sweep", "binned"}));
  app.add_option("--rebuild", opt.rebuild, "GPU rebuild methods, comma separated, or none");
  app.add_option("--frames", opt.frames, "Frames timed, uniform over the animation (default 50)");
  app.add_option("--width", opt.width, "Image width (default 1024)");
  app.add_option("--height", opt.height, "Image height (default 768)");
  app.add_option("--ao", opt.ao, "Ambient-occlusion rays per pixel (default 8)");
  app.add_option("--shadow", opt.shadow, "Shadow rays per pixel (default 2)");
  app.add_option("--traversal", opt.traversal, "simple (one thread per ray, the default), persistent or both");
  app.add_option("--layout", opt.layout, "Layouts of the refitted and rebuilt trees: bvh2, cwbvh or both comma separated (default both)");
  app.add_option("--wide-merge", opt.wideMerge,
                 "cwbvh rebuilds: binary subtrees of at most this many triangles become one wide leaf (0-8, default 0: off)")
      ->check(CLI::Range(0u, tsah::kCwbvhMaxLeafTriangles));
  app.add_flag("--no-fuse", opt.noFuse, "separate ray generation and trace kernels over every padded pixel and sample instead of the fused passes");
  app.add_option("--cwbvh-cost", opt.wideCost,
                 "cwbvh: the 8-wide collapse's cost of a node visit and of a triangle instead of the tree's objective's "
                 "(a file's own; SAH0: 3 2)")
      ->expected(2);
  app.add_option("--cwbvh-leaf", opt.wideLeaf,
                 "cwbvh: the largest leaf the 8-wide collapse makes instead of the tree's objective's (a file's own; "
                 "SAH0: 8; at most 8)")
      ->check(CLI::Range(1u, tsah::kCwbvhMaxLeafTriangles));
  app.add_flag("--ground", opt.ground, "Add the analytic ground plane (default: the meshes alone, as tsah bench)");
  app.add_flag("--no-graphs", opt.noGraphs, "Launch every kernel instead of replaying CUDA graphs");
  app.add_flag("--full-refit", opt.fullRefit, "Refit every subtree every frame, the static ones too (binary layout)");
  app.add_flag("--no-render", opt.noRender, "Time the updates and rebuilds only");
  auto* shutter = app.add_option("--shutter", opt.shutter,
                                 "Motion blur: also draw every refit frame blurred over a shutter of this fraction "
                                 "(0 to 1) of the time between timed frames, bvh2 layout (default 0: none)")
                      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--shutter-mode", opt.shutterMode, "centered (default) or open")
      ->check(CLI::IsMember({"centered", "open"}))
      ->needs(shutter);
  app.add_flag("--cpu-compare", opt.cpuCompare, "Render the first frame on the CPU too and compare the images");
  app.add_option("--image-dir", opt.imageDir, "Where --cpu-compare writes cpu.png and gpu.png");
  try {
    app.parse(argc, argv);
    if (opt.shutter > 0.0 && app.count("--layout") == 0) opt.layout = "bvh2";  // the layout blur traces
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    run(opt);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tsah_gpu_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
