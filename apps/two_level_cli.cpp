#include "two_level_cli.hpp"

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>

#include "bvh_info.hpp"
#include "cli.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/files.hpp"
#include "tsah/io/two_level_file.hpp"
#include "tsah/scene/two_level_render.hpp"

namespace tsah::cli {

bool isTwoLevelTreeFile(const std::string& path) {
  if (!looksLikeBvhFile(path)) return false;
  const InputFile in(path);
  uint32_t version = 0;
  return ::pread(in.fd(), &version, sizeof version, 8) == ssize_t(sizeof version) && version == kTbvhTwoLevelVersion;
}

anim::SceneSources loadSceneSourcesForCli(const std::string& scenePath) {
  anim::LoadOptions load = commandLineLoadOptions();
  load.resolveDataPath = dataPathResolver();
  load.warning = [](const std::string& text) { std::fprintf(stderr, "tsah: warning: %s\n", text.c_str()); };
  return anim::loadSceneSources(scenePath, load);
}

StructureChoice chooseStructure(const anim::SceneSources& scene, const TreeOptions& options) {
  return chooseObjectStructure(scene, structureChoiceOptions(options.objective));
}

nlohmann::json describeStructureChoice(const StructureChoice& choice) {
  nlohmann::json objects = nlohmann::json::array();
  for (const ObjectStructureChoice& c : choice.objects) {
    nlohmann::json o = {{"object", c.object},          {"name", c.name},       {"instances", c.instances},
                        {"moves", c.moves},            {"flatten", c.flatten}, {"flattened_triangles", c.flattenedTriangles},
                        {"reason", c.reason}};
    if (c.instancedCost >= 0.0) o["cost"] = {{"instanced", c.instancedCost}, {"flattened", c.flattenedCost}};
    objects.push_back(std::move(o));
  }
  const bool flat = choice.allFlattened();
  nlohmann::json out = {{"structure", flat ? "flat" : "two-level"},
                        {"flattened_objects", choice.flattenedObjects},
                        {"representative_frames", choice.frames},
                        {"seconds", choice.seconds},
                        {"objects", objects}};
  if (choice.decidedCost >= 0.0)
    out["whole_scene_cost"] = {{"flattened", choice.wholeFlattenedCost}, {"decided", choice.decidedCost}};
  return out;
}

void printStructureChoice(const nlohmann::json& j) {
  std::printf("auto        %s: %zu of %zu objects flattened (cost estimate over %u frames, %.2f s)\n",
              j["structure"].get<std::string>().c_str(), j["flattened_objects"].size(), j["objects"].size(),
              j["representative_frames"].get<unsigned>(), j["seconds"].get<double>());
  for (const auto& o : j["objects"])
    std::printf("object %-4u %-12s %u instance(s), %s: %s\n", o["object"].get<unsigned>(),
                ("'" + printable(o["name"].get<std::string>()) + "'").c_str(), o["instances"].get<unsigned>(),
                o["moves"].get<bool>() ? "moving" : "static", o["reason"].get<std::string>().c_str());
}

nlohmann::json describeTwoLevel(const TwoLevelScene& s) {
  nlohmann::json blases = nlohmann::json::array();
  uint32_t animated = 0;
  for (const Blas& b : s.blases) {
    const anim::Animation& source = *s.scene.sources[b.source];
    animated += b.animated ? 1 : 0;
    blases.push_back({{"source", b.source},
                      {"name", source.name()},
                      {"animated", b.animated},
                      {"triangles", source.triangleCount()},
                      {"keyframes", source.keyframeCount()},
                      {"nodes", b.bvh.nodeCount()},
                      {"build_frames", b.frameCosts.size()},
                      {"cost", b.cost},
                      {"build_s", b.info.buildSeconds}});
  }
  double average = 0.0, maximum = 0.0;
  for (double c : s.tlasFrameCosts) {
    average += c / double(s.tlasFrameCosts.size());
    maximum = std::max(maximum, c);
  }
  uint64_t nodes = 0;
  nlohmann::json ranges = nlohmann::json::array();
  for (const TlasTree& t : s.tlases) {
    nodes += t.bvh.nodeCount();
    ranges.push_back({t.range.start, t.range.end});
  }
  nlohmann::json flattened = nlohmann::json::array();
  for (uint32_t o : s.scene.flattenedObjects) flattened.push_back(s.scene.description.objects[o].name);
  return {{"structure", "two-level"},
          {"flattened_objects", flattened},
          {"blas", {{"count", s.blases.size()}, {"static", s.blases.size() - animated}, {"animated", animated}}},
          {"instances", s.instanceCount()},
          {"poses", s.poses.size()},
          {"scene_frames", s.frameTimes.size()},
          {"k", s.objective.k},
          {"tlas", {{"trees", s.tlases.size()},
                    {"nodes", nodes},
                    {"ranges", ranges},
                    {"cost", s.tlasCost},
                    {"frame_cost", {{"average", average}, {"maximum", maximum}}}}},
          {"blases", blases},
          {"bytes", {{"blas", s.blasBytes()}, {"tlas", s.tlasBytes()}, {"total", s.memoryBytes()}}}};
}

namespace {

double mib(uint64_t bytes) { return double(bytes) / (1024.0 * 1024.0); }

void printTwoLevel(const nlohmann::json& j) {
  const auto& b = j["blas"];
  std::printf("structure   two-level: %u BLAS (%u static, %u animated), %u instances, %u poses\n",
              b["count"].get<unsigned>(), b["static"].get<unsigned>(), b["animated"].get<unsigned>(),
              j["instances"].get<unsigned>(), j["poses"].get<unsigned>());
  if (!j["flattened_objects"].empty()) {
    std::string names;
    for (const auto& n : j["flattened_objects"]) names += (names.empty() ? "'" : ", '") + printable(n.get<std::string>()) + "'";
    std::printf("flattened   objects %s: one source, shown by one instance\n", names.c_str());
  }
  const auto& t = j["tlas"];
  const auto trees = t["trees"].get<unsigned>();
  std::printf("TLAS        %u tree%s, %u nodes; T-SAH cost (k=%d) %.3f over %u scene frames (per frame: average %.3f, "
              "maximum %.3f)\n",
              trees, trees == 1 ? "" : "s (one per part of the scene's time)", t["nodes"].get<unsigned>(), j["k"].get<int>(), t["cost"].get<double>(), j["scene_frames"].get<unsigned>(),
              t["frame_cost"]["average"].get<double>(), t["frame_cost"]["maximum"].get<double>());
  for (const auto& blas : j["blases"])
    std::printf("BLAS %-6u %-8s %u triangles, %u keyframes, %u nodes, cost %.3f over %u build frames, built in %.2f s  %s\n",
                blas["source"].get<unsigned>(), blas["animated"].get<bool>() ? "animated" : "static",
                blas["triangles"].get<unsigned>(), blas["keyframes"].get<unsigned>(), blas["nodes"].get<unsigned>(),
                blas["cost"].get<double>(), blas["build_frames"].get<unsigned>(), blas["build_s"].get<double>(),
                blas["name"].get<std::string>().c_str());
  const auto& m = j["bytes"];
  std::printf("memory      BLAS %.2f MiB, TLAS %.2f MiB, total with the instance table %.2f MiB\n",
              mib(m["blas"].get<uint64_t>()), mib(m["tlas"].get<uint64_t>()), mib(m["total"].get<uint64_t>()));
}

}  // namespace

void optimizeTwoLevel(anim::SceneSources scene, const std::string& input, const std::string& output,
                      const TreeOptions& options, const TlasOptions& tlas, const StructureChoice* choice, bool json,
                      double loadSeconds, bool reproducible) {
  const auto start = std::chrono::steady_clock::now();
  if (choice) scene = anim::flattenObjects(std::move(scene), choice->flattenedObjects);
  TwoLevelScene twoLevel = buildTwoLevelScene(std::move(scene), options, tlas);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  nlohmann::json j = describeTwoLevel(twoLevel);  // with the build times, whatever the file holds
  if (reproducible) {
    for (Blas& blas : twoLevel.blases) blas.info.buildSeconds = 0.0;
    for (TlasTree& t : twoLevel.tlases) t.info.buildSeconds = 0.0;
  }
  const auto saveStart = std::chrono::steady_clock::now();
  saveTwoLevelScene(output, twoLevel);
  const double saveSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - saveStart).count();
  j["input"] = input;
  j["output"] = output;
  j["structure_rule"] = choice ? "auto: " + std::to_string(choice->flattenedObjects.size()) + " of " +
                                     std::to_string(choice->objects.size()) + " objects flattened by the cost estimate"
                              : "asked for (--structure two-level)";
  if (choice) j["structure_choice"] = describeStructureChoice(*choice);
  j["build_s"] = seconds;
  nlohmann::json phases = nlohmann::json::array();
  phases.push_back({{"name", "load"}, {"seconds", loadSeconds}});
  if (choice) phases.push_back({{"name", "structure choice"}, {"seconds", choice->seconds}});
  for (const BuildPhase& p : twoLevel.buildPhases) phases.push_back({{"name", p.name}, {"seconds", p.seconds}});
  phases.push_back({{"name", "save"}, {"seconds", saveSeconds}});
  j["phases"] = phases;
  j["peak_rss_bytes"] = peakResidentBytes();  // after the save: the whole command's
  if (json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("%s: two-level scene (%s)\n", output.c_str(), j["structure_rule"].get<std::string>().c_str());
  if (choice) printStructureChoice(j["structure_choice"]);
  printTwoLevel(j);
  std::printf("build       %.2f s\n", seconds);
  std::string line;
  for (const auto& p : phases) {
    char text[96];
    std::snprintf(text, sizeof text, "%s%s %.2f s", line.empty() ? "" : ", ", p["name"].get<std::string>().c_str(),
                  p["seconds"].get<double>());
    line += text;
  }
  std::printf("phases      %s\n", line.c_str());
}

void describeTwoLevelFile(const std::string& treePath, const std::string& scenePath, bool json) {
  const TwoLevelScene twoLevel = loadTwoLevelSceneFile(treePath, loadSceneSourcesForCli(scenePath));
  nlohmann::json j = describeTwoLevel(twoLevel);
  j["format"] = "tbvh";
  j["version"] = kTbvhTwoLevelVersion;
  j["file"] = treePath;
  j["scene"] = scenePath;
  if (json) {
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("file        %s (.tbvh version 3) for %s\n", treePath.c_str(), scenePath.c_str());
  printTwoLevel(j);
}

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

class TwoLevelFrameRuntime final : public FrameRuntime {
 public:
  TwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, TwoLevelRuntime::Config config, Shutter shutter,
                       double frameInterval)
      : scene_(std::move(scene)),
        runtime_(*scene_, config),
        view_(runtime_),
        layout_(config.layout),
        tlas_(config.tlas),
        shutter_(shutter),
        frameInterval_(frameInterval) {}

  void warmUp(double, const std::function<Camera(double)>&, const SceneLighting&, const RenderSettings&) override {
    runtime_.parallelFor(64, 1, [](std::size_t, std::size_t) {});
  }

  // update: the poses' refits, the instances' transforms and the TLAS (refitMs). The world mesh
  // the renderer shades from is shading work: its time is added to the frame's shading time.
  FrameUpdate update(double time) override {
    FrameUpdate u;
    const auto start = std::chrono::steady_clock::now();
    if (shutter_.fraction > 0.0) {
      const auto [open, close] = shutterInterval(scene_->scene.start, scene_->scene.end, time, frameInterval_, shutter_);
      runtime_.updateShutter(open, close);
      u.keys = std::max<uint32_t>(1, uint32_t(runtime_.keyTimes().size()));
    } else {
      runtime_.update(time);
    }
    u.refitMs = msSince(start);
    u.updateMs = u.refitMs;
    meshMs_ = view_.updateMesh();
    return u;
  }

  FrameRender render(const Camera& camera, const SceneLighting& lighting, const RenderSettings& settings,
                     Image* image) override {
    FrameRender r;
    r.rays = renderFrame(view_, camera, lighting, settings, image ? *image : scratch_);
    r.rays.shadeMs += meshMs_;
    r.frameMs = r.rays.total().ms;
    return r;
  }

  uint32_t currentTree() const override { return 0; }

  std::string summary() const override {
    return "CPU, two-level: " + std::to_string(scene_->blases.size()) + " BLAS in " + name(layout_) +
           (runtime_.poseTriangles() == TriangleForm::Vertices ? " (poses as vertex packets)" : "") + ", " +
           std::to_string(scene_->instanceCount()) + " instances, TLAS " +
           (tlas_ == TwoLevelRuntime::TlasUpdate::Refit ? "refitted" : "rebuilt") + " per frame";
  }

  void describe(nlohmann::json& out) const override {
    out["device"] = "cpu";
    out["timer"] = "host steady clock";
    out["layout"] = name(layout_);
    out["pose_triangle_form"] = name(runtime_.poseTriangles());
    out["two_level"] = describeTwoLevel(*scene_);
    out["two_level"].erase("blases");
    out["two_level"]["tlas_update"] = tlas_ == TwoLevelRuntime::TlasUpdate::Refit ? "refit" : "rebuild";
    out["two_level"]["runtime_bytes"] = runtime_.memoryBytes();
    out["two_level"]["blas_refits"] = runtime_.blasRefits();
  }

 private:
  std::shared_ptr<const TwoLevelScene> scene_;
  TwoLevelRuntime runtime_;
  TwoLevelRenderView view_;
  Layout layout_;
  TwoLevelRuntime::TlasUpdate tlas_;
  Shutter shutter_;
  double frameInterval_ = 0.0;
  Image scratch_;
  double meshMs_ = 0.0;  // the last updateMesh
};

}  // namespace

std::unique_ptr<FrameRuntime> makeTwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, Layout layout,
                                                       unsigned threads, TwoLevelRuntime::TlasUpdate tlas,
                                                       std::optional<TriangleForm> poseTriangles, Shutter shutter,
                                                       double frameInterval) {
  TwoLevelRuntime::Config config;
  config.threads = threads;
  config.tlas = tlas;
  config.layout = layout == Layout::Auto ? fastestLayout() : layout;
  if (poseTriangles) config.poseTriangles = *poseTriangles;
  return std::make_unique<TwoLevelFrameRuntime>(std::move(scene), config, shutter, frameInterval);
}

}  // namespace tsah::cli
