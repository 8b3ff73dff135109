// tsah trace ANIMATION BVH.tbvh: per frame interpolate, refit (or rebuild), recompute Woop triangles
// and trace primary, ambient-occlusion and shadow rays on the CPU; one PNG per frame and timings.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "anim/binary_io.hpp"
#include "anim/error.hpp"
#include "bvh_info.hpp"
#include "cli.hpp"
#include "tsah/binned_sah_builder.hpp"
#include "tsah/camera.hpp"
#include "tsah/cpu_runtime.hpp"
#include "tsah/leaf_collapser.hpp"
#include "tsah/renderer.hpp"
#include "tsah/sah_builder.hpp"

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

tsah::Vec3 jsonVec3(const nlohmann::json& j, const std::string& file, const char* key) {
  if (!j.contains(key) || !j[key].is_array() || j[key].size() != 3 || !j[key][0].is_number() ||
      !j[key][1].is_number() || !j[key][2].is_number())
    throw anim::ImportError(file, std::string("'") + key + "' must be an array of three numbers");
  return {j[key][0].get<float>(), j[key][1].get<float>(), j[key][2].get<float>()};
}

// A camera file: {"eye": [x,y,z], "look_at": [x,y,z], "up": [x,y,z], "fov": degrees} for a fixed
// camera, or {"keys": [{"time": t, "eye": ..., "look_at": ..., "up": ..., "fov": ...}, ...]} for a path.
std::vector<anim::CameraKey> loadCameraFile(const std::string& path) {
  const std::vector<uint8_t> bytes = anim::readFile(path, std::size_t(1) << 24);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(bytes.begin(), bytes.end());
  } catch (const nlohmann::json::exception& e) {
    throw anim::ImportError(path, std::string("not valid JSON: ") + e.what());
  }
  auto key = [&](const nlohmann::json& k) {
    if (!k.is_object()) throw anim::ImportError(path, "a camera must be a JSON object");
    anim::CameraKey c;
    const tsah::Vec3 eye = jsonVec3(k, path, "eye"), at = jsonVec3(k, path, "look_at");
    const tsah::Vec3 up = k.contains("up") ? jsonVec3(k, path, "up") : tsah::Vec3{0, 1, 0};
    c.eye = {eye.x, eye.y, eye.z};
    c.lookAt = {at.x, at.y, at.z};
    c.up = {up.x, up.y, up.z};
    if (k.contains("fov")) {
      if (!k["fov"].is_number()) throw anim::ImportError(path, "'fov' must be a number (degrees)");
      c.fovyDegrees = k["fov"].get<float>();
    }
    if (k.contains("time")) {
      if (!k["time"].is_number()) throw anim::ImportError(path, "'time' must be a number");
      c.time = k["time"].get<double>();
    }
    tsah::Camera check{eye, at, up, c.fovyDegrees};
    try {
      tsah::validateCamera(check);
    } catch (const anim::Error& e) {
      throw anim::ImportError(path, e.what());
    }
    return c;
  };
  std::vector<anim::CameraKey> keys;
  if (j.is_object() && j.contains("keys")) {
    if (!j["keys"].is_array() || j["keys"].empty()) throw anim::ImportError(path, "'keys' must be a non-empty array");
    for (const auto& k : j["keys"]) keys.push_back(key(k));
    for (std::size_t i = 1; i < keys.size(); ++i)
      if (!(keys[i].time > keys[i - 1].time)) throw anim::ImportError(path, "camera key times must increase");
  } else {
    keys.push_back(key(j));
  }
  return keys;
}

struct FrameResult {
  uint32_t frame = 0;
  double time = 0.0;
  double interpolateMs = 0.0, refitMs = 0.0, buildMs = 0.0, updateMs = 0.0;
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

}  // namespace

TSAH_REGISTER_COMMAND(70, [](CLI::App& app) {
  auto* sub = app.add_subcommand(
      "trace", "Trace every frame with only a refit (or a rebuild): PNG per frame, update and ray-tracing times");
  struct Options {
    std::string input, bvh, device = "cpu", out = "trace", camera, eye, lookAt, up = "0,1,0", rebuild = "none";
    uint32_t frames = 0, width = 1024, height = 768, ao = 8, shadow = 2, threads = 0, seed = 1;
    float fov = 45.0f, aoDistance = 0.0f, aoFraction = 0.1f;
    bool json = false, noImages = false, noGround = false;
  };
  auto opt = std::make_shared<Options>();
  sub->add_option("ANIMATION", opt->input, "The animation (any input `tsah info` reads)")->required();
  sub->add_option("BVH", opt->bvh, "Tree from `tsah optimize` (.tbvh) built for this animation")->required();
  sub->add_option("--device", opt->device, "cpu or cuda")->check(CLI::IsMember({"cpu", "cuda"}));
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
                  "none: refit the given tree (default); sweep or binned: build a new SAH tree every frame (baseline)")
      ->check(CLI::IsMember({"none", "sweep", "binned"}));
  sub->add_option("--camera", opt->camera, "Camera JSON file: {eye, look_at, up, fov} or {keys: [{time, ...}]}");
  sub->add_option("--eye", opt->eye, "Camera position x,y,z (with --look-at)");
  sub->add_option("--look-at", opt->lookAt, "Point the camera looks at x,y,z");
  sub->add_option("--up", opt->up, "Scene up direction x,y,z (default 0,1,0)");
  sub->add_option("--fov", opt->fov, "Vertical field of view in degrees (default 45)");
  sub->add_option("--threads", opt->threads, "Worker threads (0: all cores)");
  sub->add_option("--seed", opt->seed, "Seed of the per-pixel random numbers (default 1)");
  sub->add_flag("--json", opt->json, "Print one JSON object {device, frames: [...], average: {...}}");
  sub->callback([opt] {
    namespace fs = std::filesystem;
    if (opt->device == "cuda")
      throw UsageError("the GPU runtime is not built in this version of tsah (it comes with the CUDA runtime); "
                       "use --device cpu");
    if (opt->eye.empty() != opt->lookAt.empty()) throw UsageError("--eye and --look-at go together");
    if (!opt->camera.empty() && !opt->eye.empty()) throw UsageError("give either --camera or --eye/--look-at");
    if (!(opt->fov > 0.0f && opt->fov < 180.0f)) throw UsageError("--fov must be between 0 and 180 degrees");
    if (!(opt->aoFraction > 0.0f) || !std::isfinite(opt->aoFraction)) throw UsageError("--ao-fraction must be positive");
    if (opt->aoDistance < 0.0f || !std::isfinite(opt->aoDistance)) throw UsageError("--ao-distance must be positive");
    const tsah::Vec3 up = parseVec3(opt->up, "--up");
    if (!(tsah::dot(up, up) > 0.0f)) throw UsageError("--up must not be zero");

    // Inputs: the tree is validated completely by the reader; then it must match the animation.
    tsah::BvhBuildInfo info;
    const tsah::FlatBvh flat = tsah::decodeFlatBvhFile(anim::readFile(opt->bvh), opt->bvh, &info);
    const anim::Animation a = tsah::cli::loadInput(opt->input);
    tsah::cli::checkTreeMatchesAnimation(info, opt->bvh, a, opt->input);
    tsah::CpuRuntime rt(flat, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {opt->threads});

    const uint32_t frameCount = opt->frames ? opt->frames : std::min<uint32_t>(a.keyframeCount(), 50);
    const std::vector<double> times = a.uniformTimes(frameCount);

    // Camera: a file, the command line, the animation's own camera path, or fitted to the bounds
    // of all frames (so it does not move while the animation plays).
    const anim::Bounds ab = a.bounds();
    tsah::Aabb bounds;
    bounds.extend(tsah::Vec3{ab.min[0], ab.min[1], ab.min[2]});
    bounds.extend(tsah::Vec3{ab.max[0], ab.max[1], ab.max[2]});
    const float aspect = float(opt->width) / float(opt->height);
    std::vector<anim::CameraKey> path;
    std::string cameraSource;
    tsah::Camera fixedCamera;
    if (!opt->camera.empty()) {
      path = loadCameraFile(opt->camera);
      cameraSource = opt->camera;
    } else if (!opt->eye.empty()) {
      fixedCamera = {parseVec3(opt->eye, "--eye"), parseVec3(opt->lookAt, "--look-at"), up, opt->fov};
      tsah::validateCamera(fixedCamera);
      cameraSource = "command line";
    } else if (!a.cameraPath().empty()) {
      path.assign(a.cameraPath().begin(), a.cameraPath().end());
      cameraSource = "animation camera path";
    } else {
      fixedCamera = tsah::fitCamera(bounds, up, opt->fov, aspect);
      cameraSource = "fitted to the animation bounds";
    }
    auto cameraAt = [&](double t) { return path.empty() ? fixedCamera : tsah::cameraAt(path, t); };
    tsah::SceneLighting lighting = tsah::fitLighting(bounds, cameraAt(times.front()), up, opt->aoFraction, !opt->noGround);
    if (opt->aoDistance > 0.0f) lighting.aoDistance = opt->aoDistance;

    // Per-frame rebuild baselines.
    tsah::CpuRuntime::TreeBuilder builder;
    const tsah::CostModel cost{info.ct, info.ci};
    const uint32_t maxLeaf = std::max(1u, info.maxLeafSize);
    if (opt->rebuild == "binned") {
      tsah::BinnedSahBuilder::Config c;
      c.cost = cost;
      c.maxLeafSize = maxLeaf;
      builder = [c](std::span<const tsah::Aabb> boxes) { return tsah::BinnedSahBuilder(c).build(boxes); };
    } else if (opt->rebuild == "sweep") {
      tsah::SweepSahBuilder::Config s;
      s.cost = cost;
      tsah::LeafCollapser::Config l;
      l.cost = cost;
      l.maxLeafSize = maxLeaf;
      builder = [s, l](std::span<const tsah::Aabb> boxes) {
        return tsah::LeafCollapser(l).collapse(tsah::SweepSahBuilder(s).build(boxes));
      };
    }

    if (!opt->noImages) {
      std::error_code ec;
      fs::create_directories(opt->out, ec);
      if (ec || !fs::is_directory(opt->out)) throw anim::Error(opt->out + ": cannot create the output folder");
    }
    rt.parallelFor(rt.threadCount() * 4, 1, [](std::size_t, std::size_t) {});  // start the workers before timing

    tsah::RenderSettings settings;
    settings.width = opt->width;
    settings.height = opt->height;
    settings.aoSamples = opt->ao;
    settings.shadowSamples = opt->shadow;
    settings.seed = opt->seed;
    tsah::Image image;
    std::vector<float> positions(std::size_t(a.vertexCount()) * 3);
    std::vector<FrameResult> results;
    tsah::cli::Progress progress("tracing");
    const std::string mode = opt->rebuild == "none" ? "refit" : "rebuild " + opt->rebuild;
    if (!opt->json)
      std::printf("%u frames, %ux%u, %u AO + %u shadow rays per pixel, %u threads, %s, camera %s\n", frameCount,
                  opt->width, opt->height, opt->ao, opt->shadow, rt.threadCount(), mode.c_str(), cameraSource.c_str());
    for (uint32_t f = 0; f < frameCount; ++f) {
      progress.update(f, frameCount);
      FrameResult r;
      r.frame = f;
      r.time = times[f];
      auto start = std::chrono::steady_clock::now();
      a.positionsAt(r.time, positions);
      r.interpolateMs = msSince(start);
      if (builder) {
        const auto t = rt.rebuild(positions, builder);
        r.buildMs = t.boxesMs + t.buildMs + t.flattenMs;
        r.refitMs = t.refitMs;
      } else {
        const auto s = std::chrono::steady_clock::now();
        rt.update(positions);
        r.refitMs = msSince(s);
      }
      r.updateMs = msSince(start);
      settings.frame = f;
      r.render = tsah::renderFrame(rt, cameraAt(r.time), lighting, settings, image);
      if (!opt->noImages) {
        const auto s = std::chrono::steady_clock::now();
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04u.png", f);
        r.image = (fs::path(opt->out) / name).string();
        tsah::savePng(r.image, image);
        r.pngMs = msSince(s);
      }
      results.push_back(r);
    }

    // Averages: times are means over frames, rates are total rays over total time per ray type.
    FrameResult avg;
    tsah::RenderStats sum;
    for (const FrameResult& r : results) {
      avg.interpolateMs += r.interpolateMs / frameCount;
      avg.refitMs += r.refitMs / frameCount;
      avg.buildMs += r.buildMs / frameCount;
      avg.updateMs += r.updateMs / frameCount;
      avg.render.shadeMs += r.render.shadeMs / frameCount;
      for (auto [total, part] : {std::pair{&sum.primary, &r.render.primary}, std::pair{&sum.ao, &r.render.ao},
                                 std::pair{&sum.shadow, &r.render.shadow}}) {
        total->rays += part->rays;
        total->ms += part->ms;
      }
    }
    auto traceMs = [](const tsah::RenderStats& s) { return s.total().ms; };

    if (opt->json) {
      nlohmann::json out;
      out["device"] = "cpu";
      out["threads"] = rt.threadCount();
      out["animation"] = opt->input;
      out["bvh"] = opt->bvh;
      out["method"] = info.method;
      out["rebuild"] = opt->rebuild;
      out["width"] = opt->width;
      out["height"] = opt->height;
      out["ao_rays_per_pixel"] = opt->ao;
      out["shadow_rays_per_pixel"] = opt->shadow;
      out["ao_distance"] = lighting.aoDistance;
      out["ground"] = lighting.ground;
      out["camera"] = cameraSource;
      out["triangles"] = a.triangleCount();
      nlohmann::json frames = nlohmann::json::array();
      for (const FrameResult& r : results) {
        nlohmann::json j;
        j["frame"] = r.frame;
        j["time"] = r.time;
        j["update_ms"] = r.updateMs;
        j["interpolate_ms"] = r.interpolateMs;
        j["refit_ms"] = r.refitMs;
        if (builder) j["build_ms"] = r.buildMs;
        j["trace_ms"] = traceMs(r.render);
        j["trace_ms_by_type"] = traceMsJson(r.render);
        j["shade_ms"] = r.render.shadeMs;
        j["total_ms"] = r.updateMs + traceMs(r.render);
        j["rays"] = raysJson(r.render);
        j["mrays_per_s"] = rateJson(r.render);
        if (!r.image.empty()) j["image"] = r.image;
        frames.push_back(j);
      }
      out["frames"] = frames;
      nlohmann::json av;
      av["update_ms"] = avg.updateMs;
      av["interpolate_ms"] = avg.interpolateMs;
      av["refit_ms"] = avg.refitMs;
      if (builder) av["build_ms"] = avg.buildMs;
      av["trace_ms"] = traceMs(sum) / frameCount;
      tsah::RenderStats perFrame = sum;
      for (auto* p : {&perFrame.primary, &perFrame.ao, &perFrame.shadow}) p->ms /= frameCount;
      av["trace_ms_by_type"] = traceMsJson(perFrame);
      av["shade_ms"] = avg.render.shadeMs;
      av["total_ms"] = avg.updateMs + traceMs(sum) / frameCount;
      av["mrays_per_s"] = rateJson(sum);
      out["average"] = av;
      std::printf("%s\n", out.dump().c_str());
      return;
    }
    std::printf("%5s %8s %10s %9s %9s %9s %9s %9s %9s\n", "frame", "time", "update_ms", "trace_ms", "total_ms",
                "MR/s prim", "MR/s ao", "MR/s shad", "MR/s all");
    auto row = [&](const char* label, const std::string& time, double update, const tsah::RenderStats& s,
                   double frames) {
      std::printf("%5s %8s %10.3f %9.1f %9.1f %9.2f %9.2f %9.2f %9.2f\n", label, time.c_str(), update, s.total().ms / frames,
                  update + s.total().ms / frames, s.primary.mraysPerSecond(), s.ao.mraysPerSecond(),
                  s.shadow.mraysPerSecond(), s.total().mraysPerSecond());
    };
    for (const FrameResult& r : results) {
      char time[32];
      std::snprintf(time, sizeof time, "%.3f", r.time);
      row(std::to_string(r.frame).c_str(), time, r.updateMs, r.render, 1.0);
    }
    row("avg", "-", avg.updateMs, sum, frameCount);
    std::printf("update = interpolate %.3f + %s %.3f ms per frame; shading %.1f ms (not in total)\n",
                avg.interpolateMs, builder ? "rebuild" : "refit+Woop", avg.updateMs - avg.interpolateMs,
                avg.render.shadeMs);
    if (!opt->noImages) std::printf("images in %s/frame_NNNN.png\n", opt->out.c_str());
  });
});
