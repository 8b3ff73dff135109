#include "trace_report.hpp"

#include <algorithm>
#include <cstdio>

#include "tsah/base/error.hpp"

namespace tsah::cli {

namespace {

nlohmann::json passesJson(const RenderStats& s, auto value) {
  return {{"primary", value(s.primary)}, {"ao", value(s.ao)}, {"shadow", value(s.shadow)}};
}

// What must agree between the chunks of one run.
constexpr const char* kRunKeys[] = {"animation", "bvh",    "method",  "trees",  "rebuild",  "width",
                                    "height",    "ao_rays_per_pixel", "shadow_rays_per_pixel",
                                    "ao_distance", "ground", "camera", "triangles", "seed", "run_frames",
                                    "layout"};

}  // namespace

nlohmann::json frameJson(const FrameResult& r, bool rebuilds) {
  const double traceMs = r.render.total().ms;
  nlohmann::json j;
  j["frame"] = r.frame;
  j["time"] = r.time;
  if (!rebuilds) j["tree"] = r.tree;
  j["update_ms"] = r.update.updateMs;
  j["keys"] = r.update.keys;  // the shutter's key times (1: the instant)
  j["interpolate_ms"] = r.update.interpolateMs;
  j["refit_ms"] = r.update.refitMs;
  if (rebuilds) j["build_ms"] = r.update.buildMs;
  j["trace_ms"] = traceMs;
  j["trace_ms_by_type"] = passesJson(r.render, [](const RayPassStats& p) { return p.ms; });
  j["shade_ms"] = r.render.shadeMs;
  j["frame_ms"] = r.frameMs;
  j["total_ms"] = r.update.updateMs + r.frameMs;
  nlohmann::json rays = passesJson(r.render, [](const RayPassStats& p) { return p.rays; });
  rays["total"] = r.render.total().rays;
  j["rays"] = rays;
  nlohmann::json rate = passesJson(r.render, [](const RayPassStats& p) { return p.mraysPerSecond(); });
  rate["total"] = r.render.total().mraysPerSecond();
  j["mrays_per_s"] = rate;
  if (!r.image.empty()) j["image"] = r.image;
  return j;
}

FrameResult frameFromJson(const nlohmann::json& j) {
  FrameResult r;
  r.frame = j.at("frame").get<uint32_t>();
  r.time = j.at("time").get<double>();
  r.tree = j.value("tree", 0u);
  r.update.updateMs = j.at("update_ms").get<double>();
  r.update.keys = j.value("keys", 1u);
  r.update.interpolateMs = j.at("interpolate_ms").get<double>();
  r.update.refitMs = j.at("refit_ms").get<double>();
  r.update.buildMs = j.value("build_ms", 0.0);
  for (auto [pass, name] : {std::pair{&r.render.primary, "primary"}, std::pair{&r.render.ao, "ao"},
                            std::pair{&r.render.shadow, "shadow"}}) {
    pass->ms = j.at("trace_ms_by_type").at(name).get<double>();
    pass->rays = j.at("rays").at(name).get<uint64_t>();
  }
  r.render.shadeMs = j.at("shade_ms").get<double>();
  r.frameMs = j.at("frame_ms").get<double>();
  r.image = j.value("image", std::string());
  return r;
}

void setFrames(nlohmann::json& run, std::vector<FrameResult> frames) {
  std::sort(frames.begin(), frames.end(), [](const FrameResult& a, const FrameResult& b) { return a.frame < b.frame; });
  const bool rebuilds = run.at("rebuild").get<std::string>() != "none";
  const double n = double(frames.size());
  FrameUpdate avg;
  RenderStats sum;
  double frameMs = 0.0;
  nlohmann::json list = nlohmann::json::array();
  for (const FrameResult& r : frames) {
    list.push_back(frameJson(r, rebuilds));
    avg.interpolateMs += r.update.interpolateMs / n;
    avg.refitMs += r.update.refitMs / n;
    avg.buildMs += r.update.buildMs / n;
    avg.updateMs += r.update.updateMs / n;
    sum.shadeMs += r.render.shadeMs / n;
    frameMs += r.frameMs / n;
    for (auto [total, part] : {std::pair{&sum.primary, &r.render.primary}, std::pair{&sum.ao, &r.render.ao},
                               std::pair{&sum.shadow, &r.render.shadow}}) {
      total->rays += part->rays;
      total->ms += part->ms;
    }
  }
  run["frames"] = list;
  nlohmann::json av;
  av["update_ms"] = avg.updateMs;
  av["interpolate_ms"] = avg.interpolateMs;
  av["refit_ms"] = avg.refitMs;
  if (rebuilds) av["build_ms"] = avg.buildMs;
  av["trace_ms"] = sum.total().ms / n;
  av["trace_ms_by_type"] = passesJson(sum, [n](const RayPassStats& p) { return p.ms / n; });
  av["shade_ms"] = sum.shadeMs;
  av["frame_ms"] = frameMs;
  av["total_ms"] = avg.updateMs + frameMs;
  nlohmann::json rate = passesJson(sum, [](const RayPassStats& p) { return p.mraysPerSecond(); });
  rate["total"] = sum.total().mraysPerSecond();
  av["mrays_per_s"] = rate;
  run["average"] = av;
}

void printTraceSummary(const nlohmann::json& run) {
  std::printf("%5s %8s %10s %9s %9s %9s %9s %9s %9s\n", "frame", "time", "update_ms", "trace_ms", "total_ms",
              "MR/s prim", "MR/s ao", "MR/s shad", "MR/s all");
  auto row = [](const std::string& label, const std::string& time, const nlohmann::json& j) {
    const nlohmann::json& rate = j.at("mrays_per_s");
    std::printf("%5s %8s %10.3f %9.3f %9.3f %9.2f %9.2f %9.2f %9.2f\n", label.c_str(), time.c_str(),
                j.at("update_ms").get<double>(), j.at("trace_ms").get<double>(), j.at("total_ms").get<double>(),
                rate.at("primary").get<double>(), rate.at("ao").get<double>(), rate.at("shadow").get<double>(),
                rate.at("total").get<double>());
  };
  for (const nlohmann::json& f : run.at("frames")) {
    char time[32];
    std::snprintf(time, sizeof time, "%.3f", f.at("time").get<double>());
    row(std::to_string(f.at("frame").get<uint32_t>()), time, f);
  }
  const nlohmann::json& av = run.at("average");
  row("avg", "-", av);
  const double update = av.at("update_ms").get<double>(), interpolate = av.at("interpolate_ms").get<double>();
  std::printf("update = interpolate %.3f + %s %.3f ms per frame; total = update + the whole frame %.3f ms "
              "(shading %.3f ms%s)\n",
              interpolate, run.at("rebuild").get<std::string>() != "none" ? "rebuild" : "refit",
              update - interpolate, av.at("frame_ms").get<double>(), av.at("shade_ms").get<double>(),
              run.contains("gpu")
                  ? " and the download in it; trace_ms sums the ray passes, which overlap"
                  : ", not in it");
  if (run.contains("images")) std::printf("images in %s/frame_NNNN.png\n", run.at("images").get<std::string>().c_str());
}

nlohmann::json mergeChunks(const std::vector<std::pair<std::string, nlohmann::json>>& chunks) {
  struct Chunk {
    const std::string* file;
    const nlohmann::json* run;
    uint32_t start, end;
  };
  std::vector<Chunk> sorted;
  for (const auto& [file, run] : chunks) {
    if (!run.is_object() || !run.contains("range") || !run.contains("frames") || !run.contains("run_frames"))
      throw FileError(file, "not the statistics of `tsah trace --stats` (no range, frames or run_frames)");
    if (!run.at("frames").is_array() || !run.at("run_frames").is_number_unsigned() ||
        !run.value("rebuild", nlohmann::json()).is_string())
      throw FileError(file, "frames must be a list, run_frames a count and rebuild a name");
    const nlohmann::json& range = run.at("range");
    if (!range.is_array() || range.size() != 2 || !range[0].is_number_unsigned() || !range[1].is_number_unsigned())
      throw FileError(file, "range must be [start, end]");
    sorted.push_back({&file, &run, range[0].get<uint32_t>(), range[1].get<uint32_t>()});
  }
  if (sorted.empty()) throw ConfigError("tsah report: no statistics files given");
  std::sort(sorted.begin(), sorted.end(), [](const Chunk& a, const Chunk& b) { return a.start < b.start; });
  const Chunk& first = sorted.front();
  for (const Chunk& c : sorted)
    for (const char* key : kRunKeys)
      if (c.run->value(key, nlohmann::json()) != first.run->value(key, nlohmann::json()))
        throw FileError(*c.file, "another run than " + *first.file + " (its " + key + " differs)");
  const uint32_t total = first.run->at("run_frames").get<uint32_t>();
  uint32_t next = 0;
  std::vector<FrameResult> frames;
  for (const Chunk& c : sorted) {
    if (c.start < next)
      throw FileError(*c.file, "frames " + std::to_string(c.start) + ".." + std::to_string(next - 1) +
                                   " are also in another chunk");
    if (c.start > next)
      throw DataError("frames " + std::to_string(next) + ".." + std::to_string(c.start - 1) + " of " +
                      std::to_string(total) + " are in no chunk (the next is " + *c.file + ")");
    try {
      for (const nlohmann::json& f : c.run->at("frames")) frames.push_back(frameFromJson(f));
    } catch (const nlohmann::json::exception& e) {
      throw FileError(*c.file, std::string("a frame entry is incomplete (") + e.what() + ")");
    }
    if (c.end < c.start || c.run->at("frames").size() != c.end - c.start)
      throw FileError(*c.file, "its range holds " + std::to_string(c.end - c.start) + " frames, its list " +
                                   std::to_string(c.run->at("frames").size()));
    next = c.end;
  }
  if (next != total)
    throw DataError("frames " + std::to_string(next) + ".." + std::to_string(total - 1) + " of " +
                    std::to_string(total) + " are in no chunk (the last is " + *sorted.back().file + ")");
  nlohmann::json run = *first.run;
  run["range"] = {0, total};
  // The images' folder where every chunk wrote into the same one (each frame names its PNG anyway).
  for (const Chunk& c : sorted)
    if (c.run->value("images", nlohmann::json()) != run.value("images", nlohmann::json())) run.erase("images");
  setFrames(run, std::move(frames));
  return run;
}

}  // namespace tsah::cli
