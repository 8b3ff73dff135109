// tsah trace ANIMATION BVH.tbvh: per frame interpolate, refit (or rebuild), recompute Woop triangles
// and trace primary, ambient-occlusion and shadow rays, on the CPU (tsah::CpuRuntime) or on the GPU
// (tsah::cuda::GpuRuntime); one PNG per frame and timings.
#include <algorithm>
#include <atomic>
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
#include "tsah/base/memory.hpp"
#include "bvh_info.hpp"
#include "camera_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "cli.hpp"
#include "frame_runtime.hpp"
#include "scale_out.hpp"
#include "trace_report.hpp"
#include "two_level_cli.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/camera_path.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/render/renderer.hpp"
#if TSAH_HAVE_CUDA
#include "tsah_cuda/device.hpp"
#endif

namespace {

using tsah::cli::UsageError;

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
  std::string input, bvh, out = "trace", camera, eye, lookAt, up = "0,1,0", rebuild = "none";
  tsah::Device device = tsah::Device::Cpu;
  tsah::Layout layout = tsah::Layout::Auto;  // tree layout (CPU or GPU)
  std::string isa = "auto";                  // the CPU's SIMD kernels
  std::string triangles = "auto";            // how the CPU's wide trees hold triangles (auto: the runtime's)
  uint32_t frames = 0, width = 1024, height = 768, ao = 8, shadow = 2, threads = 0, seed = 1;
  float fov = 45.0f, aoDistance = 0.0f, aoFraction = 0.1f;
  bool json = false, noImages = false, noGround = false;
  std::string range;    // START:END, half-open over the frame indices (empty: every frame)
  std::string stats;    // file for the JSON statistics (--stats)
  std::string devices;  // --devices all|0,2,...
  tsah::cli::ShutterOptions shutter;  // motion blur: --shutter, --shutter-mode
  std::string tlas;  // two-level trees: refit (default) | rebuild (CPU) | lbvh | hlbvh-sah (GPU)
};

// --shutter: the shutter of each frame; usage errors for values and combinations it cannot serve
// (checked before the device is looked for). The frame count is checked once the input is read.
// twoLevel: the tree is a two-level scene, which the GPU blurs with its BLAS in either layout.
tsah::Shutter parseShutter(const TraceOptions& opt, bool twoLevel) {
  const tsah::Shutter shutter = opt.shutter.checked("the time between frames");
  if (shutter.fraction == 0.0) return shutter;
  if (opt.rebuild != "none") throw UsageError("--shutter refits the given tree; it does not go with --rebuild");
  // The CPU traces blurred frames in every layout it has; the GPU a flat tree in the binary one.
  if (!twoLevel && opt.device == tsah::Device::Cuda && opt.layout != tsah::Layout::Auto &&
      opt.layout != tsah::Layout::Bvh2)
    throw UsageError("--shutter traces the bvh2 layout on the GPU (--layout bvh2 or auto)");
  return shutter;
}

void checkDeviceAndLayout(const TraceOptions& opt) {
  tsah::cli::checkLayoutForDevice(opt.layout, opt.device);
  if (opt.device != tsah::Device::Cuda) return;
#if TSAH_HAVE_CUDA
  if (!tsah::cuda::deviceAvailable())
    throw UsageError("no CUDA device found (no GPU, no NVIDIA driver, or CUDA_VISIBLE_DEVICES hides them); "
                     "use --device cpu");
#else
  throw UsageError("the GPU runtime is not built in this version of tsah (configure with a CUDA compiler to "
                   "build it); use --device cpu");
#endif
}

// What a two-level tree (.tbvh version 3) is not traced with: a per-frame rebuild of the whole
// scene (--rebuild; the TLAS's is --tlas rebuild), several GPUs or the CPU's SIMD kernels of flat
// trees; on the GPU, the compressed layout. The TLAS rebuilds of one device only.
void checkTwoLevelOptions(const TraceOptions& opt, const tsah::cli::FrameRuntimeOptions& runtimeOptions) {
  if (runtimeOptions.rebuild != tsah::cli::Rebuild::None || !opt.devices.empty() || runtimeOptions.isa)
    throw UsageError(opt.bvh + " holds a two-level scene: it is traced without --devices, --rebuild (see --tlas "
                     "rebuild) or --isa");
  const bool gpuRebuild = opt.tlas == "lbvh" || opt.tlas == "hlbvh-sah";
  if (opt.device != tsah::Device::Cuda) {
    if (gpuRebuild)
      throw UsageError("--tlas " + opt.tlas + " rebuilds the TLAS on the GPU: use it with --device cuda (on the CPU: "
                       "--tlas rebuild)");
    return;
  }
  if (opt.tlas == "rebuild")
    throw UsageError("--tlas rebuild builds a sweep-SAH TLAS on the CPU: with --device cuda use --tlas lbvh or "
                     "hlbvh-sah (or trace with --device cpu)");
}

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void runTrace(const TraceOptions& opt) {
  const auto started = std::chrono::steady_clock::now();
  namespace fs = std::filesystem;
  tsah::cli::FrameRuntimeOptions runtimeOptions;
  runtimeOptions.device = opt.device;
  runtimeOptions.layout = opt.layout;
  if (opt.isa != "auto") runtimeOptions.isa = tsah::parse<tsah::SimdIsa>(opt.isa);
  if (runtimeOptions.isa && opt.device == tsah::Device::Cuda)
    throw UsageError("--isa chooses the CPU's kernels; it does not go with --device cuda");
  if (opt.triangles != "auto") runtimeOptions.triangles = tsah::parse<tsah::TriangleForm>(opt.triangles);
  if (runtimeOptions.triangles && opt.device == tsah::Device::Cuda)
    throw UsageError("--triangles chooses how the CPU's wide trees hold triangles; it does not go with --device cuda");
  if (runtimeOptions.triangles == tsah::TriangleForm::Vertices && opt.layout == tsah::Layout::Bvh2)
    throw UsageError("--triangles vertices needs a wide layout (--layout bvh4, bvh8 or auto); bvh2 holds Woop triangles");
  runtimeOptions.threads = opt.threads;
  runtimeOptions.rebuild = tsah::cli::parseRebuild(opt.rebuild);
  tsah::cli::checkRebuildForDevice(runtimeOptions.rebuild, opt.device);
  if (!opt.devices.empty() && opt.device != tsah::Device::Cuda)
    throw UsageError("--devices chooses GPUs: use it with --device cuda");
  const std::vector<int> devices = !opt.devices.empty() ? tsah::cli::parseDevices(opt.devices)
                                   : std::vector<int>{opt.device == tsah::Device::Cuda ? tsah::cli::rankDevice() : 0};
  // A two-level tree (version 3) is refused the options it cannot serve before the device is looked
  // for, so the message is the same on every machine.
  const bool twoLevel = tsah::cli::isTwoLevelTreeFile(opt.bvh);
  runtimeOptions.shutter = parseShutter(opt, twoLevel);
  if (twoLevel) checkTwoLevelOptions(opt, runtimeOptions);
  checkDeviceAndLayout(opt);
  if (opt.eye.empty() != opt.lookAt.empty()) throw UsageError("--eye and --look-at go together");
  if (!opt.camera.empty() && !opt.eye.empty()) throw UsageError("give either --camera or --eye/--look-at");
  if (!(opt.fov > 0.0f && opt.fov < 180.0f)) throw UsageError("--fov must be between 0 and 180 degrees");
  if (!(opt.aoFraction > 0.0f) || !std::isfinite(opt.aoFraction)) throw UsageError("--ao-fraction must be positive");
  if (opt.aoDistance < 0.0f || !std::isfinite(opt.aoDistance)) throw UsageError("--ao-distance must be positive");
  const tsah::Vec3 up = parseVec3(opt.up, "--up");
  if (!(tsah::dot(up, up) > 0.0f)) throw UsageError("--up must not be zero");

  // Inputs: the tree (or tree set: each frame refits the tree of its part) is validated completely
  // by the reader; then it must match the animation. A two-level tree (version 3) is read with its
  // scene, which checks that it was built for it.
  std::shared_ptr<const tsah::TwoLevelScene> twoLevelScene;
  tsah::TreeSet trees;
  if (twoLevel) {
    if (!anim::isSceneFile(opt.input))
      throw UsageError(opt.bvh + " holds a two-level scene: trace it with its scene file, not " + opt.input);
    twoLevelScene = std::make_shared<const tsah::TwoLevelScene>(
        tsah::loadTwoLevelSceneFile(opt.bvh, tsah::cli::loadSceneSourcesForCli(opt.input)));
  } else {
    if (!opt.tlas.empty())
      throw UsageError("--tlas goes with a two-level tree (.tbvh version 3); " + opt.bvh + " is a flat tree");
    trees = tsah::decodeTreeSetFile(tsah::readFile(opt.bvh), opt.bvh);
  }
  const tsah::BvhBuildInfo& info = twoLevel ? twoLevelScene->tlases.front().info : trees.builds.front();
  const anim::Animation a = tsah::cli::loadInput(opt.input);
  if (!twoLevel) tsah::cli::checkTreeMatchesAnimation(info, opt.bvh, a, opt.input);
  runtimeOptions.objective = info.objective;
  const uint32_t frameCount = opt.frames ? opt.frames : std::min<uint32_t>(a.keyframeCount(), 50);
  const auto [first, end] = tsah::cli::parseFrameRange(opt.range, frameCount);
  const std::vector<double> times = a.uniformTimes(frameCount);
  if (runtimeOptions.shutter.fraction > 0.0) {
    if (frameCount < 2)
      throw UsageError("--shutter needs at least two frames (it is a fraction of the time between them)");
    if (opt.device == tsah::Device::Cuda) runtimeOptions.layout = tsah::Layout::Bvh2;  // the GPU's blurred layout
    runtimeOptions.frameInterval = times[1] - times[0];
  }
  // One runtime per GPU of --devices (each on its own GPU), else one: the CPU, or the GPU of this
  // rank.
  std::vector<std::unique_ptr<tsah::cli::FrameRuntime>> runtimes;
  for (int gpu : devices) {
    runtimeOptions.gpu = gpu;
    if (!twoLevel)
      runtimes.push_back(tsah::cli::makeFrameRuntime(trees, a, runtimeOptions));
    else if (opt.device == tsah::Device::Cuda)
      runtimes.push_back(tsah::cli::makeGpuTwoLevelFrameRuntime(twoLevelScene, gpu, opt.layout,
                                                                opt.tlas.empty() ? "refit" : opt.tlas,
                                                                runtimeOptions.shutter, runtimeOptions.frameInterval));
    else
      runtimes.push_back(tsah::cli::makeTwoLevelFrameRuntime(twoLevelScene, runtimeOptions.layout, runtimeOptions.threads,
                                                             opt.tlas == "rebuild"
                                                                 ? tsah::TwoLevelRuntime::TlasUpdate::Rebuild
                                                                 : tsah::TwoLevelRuntime::TlasUpdate::Refit,
                                                             runtimeOptions.triangles, runtimeOptions.shutter, runtimeOptions.frameInterval));
  }
  const tsah::cli::FrameRuntime& rt = *runtimes.front();

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
  // The frame's buffers on either device (the CPU renderer's, or the host side of the GPU's) and its
  // PNG (the raw rows and at most as much compressed), one of each per runtime, stated before the
  // first frame is rendered.
  const std::size_t pngBytes = opt.noImages ? 0 : std::size_t(opt.width) * opt.height * 3 * 2;
  tsah::checkFitsInMemory((tsah::renderFrameBytes(settings, a.vertexCount()) + pngBytes) * runtimes.size(), opt.input,
                          "tracing " + std::to_string(opt.width) + "x" + std::to_string(opt.height) + " frames");
  const bool rebuilds = opt.rebuild != "none";
  char blur[64] = "";
  if (runtimeOptions.shutter.fraction > 0.0)
    std::snprintf(blur, sizeof blur, ", shutter %g %s", opt.shutter.fraction, opt.shutter.mode.c_str());
  const std::string mode =
      twoLevel ? "two-level, TLAS " +
                     std::string(opt.tlas == "rebuild"     ? "rebuilt (sweep SAH)"
                                 : opt.tlas == "lbvh"      ? "rebuilt (LBVH, GPU)"
                                 : opt.tlas == "hlbvh-sah" ? "rebuilt (HLBVH-SAH, GPU)"
                                                           : "refitted") +
                     " every frame" + blur
      : rebuilds ? "rebuild " + opt.rebuild + (tsah::cli::isGpuRebuild(runtimeOptions.rebuild) ? " (GPU)" : " (CPU)")
               : trees.size() > 1 ? "refit of the tree of each frame's part (" + std::to_string(trees.size()) + " trees)"
                                  : std::string("refit") + blur;
  const bool leader = tsah::cli::job::leader();
  if (!opt.json && leader)
    std::printf("%u frames, %ux%u, %u AO + %u shadow rays per pixel, %s%s, %s, camera %s\n", end - first, opt.width,
                opt.height, opt.ao, opt.shadow, rt.summary().c_str(),
                runtimes.size() > 1 ? (" (x" + std::to_string(runtimes.size()) + ")").c_str() : "", mode.c_str(),
                cameraSource.c_str());
  std::fflush(stdout);

  // The frames of the range, dealt to the runtimes (and the ranks of an MPI job); each frame's
  // picture depends on its index only, so who renders it does not matter.
  std::vector<tsah::Image> images(runtimes.size());
  std::atomic<uint32_t> done{0};
  tsah::cli::Progress progress("tracing");
  for (const auto& runtime : runtimes) runtime->warmUp(times.front(), cameraAt, lighting, settings);
  const double loadSeconds = secondsSince(started);
  const auto loopStart = std::chrono::steady_clock::now();
  const auto dealer = tsah::cli::makeDealer(unsigned(runtimes.size()));
  const std::vector<uint32_t> units = tsah::unitRange(first, end);
  const std::vector<tsah::UnitResult> results = dealer->deal(units, [&](uint32_t f, unsigned w) {
    tsah::cli::FrameResult r;
    r.frame = f;
    r.time = times[f];
    r.update = runtimes[w]->update(r.time);
    r.tree = runtimes[w]->currentTree();
    tsah::RenderSettings frameSettings = settings;
    frameSettings.frame = f;
    const tsah::cli::FrameRender rendered =
        runtimes[w]->render(cameraAt(r.time), lighting, frameSettings, opt.noImages ? nullptr : &images[w]);
    r.render = rendered.rays;
    r.frameMs = rendered.frameMs;
    if (!opt.noImages) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%04u.png", f);
      r.image = (fs::path(opt.out) / name).string();
      tsah::savePng(r.image, images[w]);
    }
    ++done;
    if (w == 0) progress.update(done, units.size() / std::size_t(tsah::cli::job::size()));  // one thread prints
    const std::string text = tsah::cli::frameJson(r, rebuilds).dump();
    return tsah::UnitResult(text.begin(), text.end());
  });
  const double loopSeconds = secondsSince(loopStart);
  if (!leader) return;

  nlohmann::json out;
  rt.describe(out);
  if (runtimes.size() > 1 || tsah::cli::job::size() > 1)
    out["workers"] = {{"ranks", tsah::cli::job::size()}, {"runtimes_per_rank", runtimes.size()}};
  out["animation"] = opt.input;
  out["bvh"] = opt.bvh;
  out["method"] = info.method;
  out["trees"] = trees.size();
  out["structure"] = twoLevel ? "two-level" : "flat";
  out["rebuild"] = opt.rebuild;
  out["width"] = opt.width;
  out["height"] = opt.height;
  out["ao_rays_per_pixel"] = opt.ao;
  out["shadow_rays_per_pixel"] = opt.shadow;
  out["ao_distance"] = lighting.aoDistance;
  out["ground"] = lighting.ground;
  out["camera"] = cameraSource;
  out["triangles"] = a.triangleCount();
  out["seed"] = opt.seed;
  out["shutter"] = {{"fraction", opt.shutter.fraction}, {"mode", opt.shutter.mode}};
  out["run_frames"] = frameCount;
  out["range"] = {first, end};
  // Wall time on rank 0: reading, baking and uploading up to the warmed-up runtimes; the frame
  // loop (update, trace, shading, PNG written) of the whole range, every rank's frames gathered.
  out["wall_s"] = {{"load", loadSeconds}, {"frames", loopSeconds}};
  if (!opt.noImages) out["images"] = opt.out;
  std::vector<tsah::cli::FrameResult> frames;
  for (const tsah::UnitResult& bytes : results)
    frames.push_back(tsah::cli::frameFromJson(nlohmann::json::parse(bytes.begin(), bytes.end())));
  tsah::cli::setFrames(out, std::move(frames));
  if (!opt.stats.empty()) {
    const std::string text = out.dump() + "\n";
    tsah::writeFileAtomically(opt.stats, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
  }
  if (opt.json)
    std::printf("%s\n", out.dump().c_str());
  else
    tsah::cli::printTraceSummary(out);
}

}  // namespace

TSAH_REGISTER_COMMAND(70, [](CLI::App& app) {
  auto* sub = app.add_subcommand(
      "trace", "Trace every frame with only a refit (or a rebuild): PNG per frame, update and ray-tracing times");
  auto opt = std::make_shared<TraceOptions>();
  sub->add_option("ANIMATION", opt->input, "The animation (any input `tsah info` reads)")->required();
  sub->add_option("BVH", opt->bvh, "Tree from `tsah optimize` (.tbvh) built for this animation (a two-level tree: for this scene file)")->required();
  tsah::cli::addChoice(*sub, "--device", opt->device,
                       "cpu (default) or cuda (the GPU runtime, when built and a GPU is present)",
                       {tsah::Device::Cpu, tsah::Device::Cuda});
  sub->add_option("--frames", opt->frames,
                  "Frames to trace, uniform over the animation's time range (default: one per keyframe, at most 50)")
      ->check(CLI::Range(1u, 100000u));
  sub->add_option("--width", opt->width, "Image width (default 1024)")->check(CLI::Range(1u, 16384u));
  sub->add_option("--height", opt->height, "Image height (default 768)")->check(CLI::Range(1u, 16384u));
  sub->add_option("--ao", opt->ao, "Ambient-occlusion rays per pixel (default 8)")->check(CLI::Range(0u, 1024u));
  sub->add_option("--shadow", opt->shadow, "Shadow rays per pixel (default 2)")->check(CLI::Range(0u, 1024u));
  // Pairs where one option would silently override the other are refused (exit 2).
  auto* aoDistance = sub->add_option("--ao-distance", opt->aoDistance,
                                     "Maximum AO ray length (default: --ao-fraction of the scene diagonal)");
  sub->add_option("--ao-fraction", opt->aoFraction, "AO ray length as a fraction of the scene diagonal (default 0.1)")
      ->excludes(aoDistance);
  auto* out = sub->add_option("--out", opt->out, "Folder for frame_NNNN.png (default ./trace)");
  sub->add_flag("--no-images", opt->noImages, "Do not write PNG files (timing runs)")->excludes(out);
  sub->add_flag("--no-ground", opt->noGround, "No ground plane: only the animated mesh (as in the paper's runs)");
  sub->add_option("--rebuild", opt->rebuild,
                  "none: refit the given tree (default); otherwise build a new tree every frame (baseline): "
                  "sweep or binned SAH on the CPU (--device cpu), lbvh or hlbvh-sah on the GPU (--device cuda; "
                  "with --layout cwbvh each rebuilt tree is converted to the compressed 8-wide layout on the GPU, "
                  "and the conversion counts in the update)")
      ->check(CLI::IsMember({"none", "sweep", "binned", "lbvh", "hlbvh-sah"}));
  sub->add_option("--tlas", opt->tlas,
                  "A two-level tree (.tbvh version 3): refit (default: the top-level tree optimized over the "
                  "scene's frames, refitted) or a top-level tree built every frame, the reference: rebuild (sweep "
                  "SAH, --device cpu), lbvh or hlbvh-sah (--device cuda)")
      ->check(CLI::IsMember({"refit", "rebuild", "lbvh", "hlbvh-sah"}));
  sub->add_option("--camera", opt->camera, "Camera JSON file: {eye, look_at, up, fov} or {keys: [{time, ...}]}");
  sub->add_option("--eye", opt->eye, "Camera position x,y,z (with --look-at)");
  sub->add_option("--look-at", opt->lookAt, "Point the camera looks at x,y,z");
  sub->add_option("--up", opt->up, "Scene up direction x,y,z (default 0,1,0)");
  sub->add_option("--fov", opt->fov, "Vertical field of view in degrees (default 45)");
  sub->add_option("--threads", opt->threads, "CPU worker threads (0: all cores)");
  tsah::cli::addChoice(*sub, "--layout", opt->layout,
                       "Tree layout: CPU bvh2 (the binary tree), bvh4 or bvh8 (wide trees collapsed from it at load "
                  "time); GPU bvh2 or cwbvh (compressed 8-wide, docs/cwbvh.md; for the refitted tree and the "
                  "--rebuild trees); default auto: on the CPU the widest "
                  "the processor's SIMD kernels (or --isa's) support, on the GPU the runtime's default",
                       {tsah::Layout::Auto, tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8, tsah::Layout::Cwbvh});
  sub->add_option("--isa", opt->isa, "CPU SIMD kernels of a wide layout: sse, avx2 or avx512 (default auto: the best)")
      ->check(CLI::IsMember({"auto", "sse", "avx2", "avx512"}));
  sub->add_option("--triangles", opt->triangles,
                  "CPU bvh4/bvh8: how the tree holds each frame's triangles, woop (Woop packets) or vertices "
                  "(vertex packets, no Woop rows to compute per refit); default auto: woop, and for a two-level "
                  "tree its poses as vertices (its static objects always woop)")
      ->check(CLI::IsMember({"auto", "woop", "vertices"}));
  sub->add_option("--seed", opt->seed, "Seed of the per-pixel random numbers (default 1)");
  opt->shutter.add(*sub,
                   "Motion blur: the shutter's length as a fraction of the time between traced frames, "
                   "0 to 1 (default 0: the instant); each frame is refitted at the shutter's key times "
                   "and each pixel traced at its own time (CPU: bvh2, bvh4, bvh8; GPU: bvh2; docs/motion-blur.md)",
                   "centered: the shutter around the frame's time (default); open: starting at it");
  sub->add_flag("--json", opt->json, "Print one JSON object {device, frames: [...], average: {...}}");
  sub->add_option("--range", opt->range,
                  "START:END: only the frames START .. END-1 of the run (half-open, over the frame indices of "
                  "--frames), with the same pictures and figures as in the whole run (a render farm's chunk)");
  sub->add_option("--stats", opt->stats,
                  "Also write the JSON object of --json to this file (a chunk's statistics: `tsah report` merges them)");
  sub->add_option("--devices", opt->devices,
                  "With --device cuda: all, or GPU indices such as 0,2: one runtime per GPU, frames dealt to them");
  sub->callback([opt] { runTrace(*opt); });
});
