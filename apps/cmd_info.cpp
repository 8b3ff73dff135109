// tsah info INPUT [--json]: what an input holds.
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "anim/scene.hpp"
#include "bvh_info.hpp"
#include "cli.hpp"
#include "two_level_cli.hpp"

namespace {

nlohmann::json describe(const anim::Animation& a, double loadSeconds) {
  const anim::Bounds b = a.bounds();
  const anim::Bounds b0 = a.keyframeBounds(0);
  nlohmann::json j;
  j["name"] = a.name();
  j["frames"] = a.keyframeCount();
  j["triangles"] = a.triangleCount();
  j["vertices"] = a.vertexCount();
  j["degenerate_triangles"] = a.degenerateTriangleCount();
  j["time"] = {a.startTime(), a.endTime()};
  j["bounds"] = {{b.min[0], b.min[1], b.min[2]}, {b.max[0], b.max[1], b.max[2]}};
  j["first_frame_bounds"] = {{b0.min[0], b0.min[1], b0.min[2]}, {b0.max[0], b0.max[1], b0.max[2]}};
  j["camera_keys"] = a.cameraPath().size();
  j["moving_vertices"] = a.movingVertexCount();
  j["memory_bytes"] = a.memoryBytes();
  j["load_s"] = loadSeconds;
  return j;
}

void printText(const nlohmann::json& j) {
  auto triple = [](const nlohmann::json& v) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "(%.4g, %.4g, %.4g)", v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
    return std::string(buf);
  };
  std::printf("name        %s\n", j["name"].get<std::string>().c_str());
  std::printf("keyframes   %u\n", j["frames"].get<unsigned>());
  std::printf("triangles   %u (%u degenerate)\n", j["triangles"].get<unsigned>(), j["degenerate_triangles"].get<unsigned>());
  std::printf("vertices    %u (%u moving)\n", j["vertices"].get<unsigned>(), j["moving_vertices"].get<unsigned>());
  std::printf("time        %g .. %g\n", j["time"][0].get<double>(), j["time"][1].get<double>());
  std::printf("bounds      %s .. %s\n", triple(j["bounds"][0]).c_str(), triple(j["bounds"][1]).c_str());
  std::printf("frame 0     %s .. %s\n", triple(j["first_frame_bounds"][0]).c_str(), triple(j["first_frame_bounds"][1]).c_str());
  if (j["camera_keys"].get<std::size_t>() > 0)
    std::printf("camera      %zu keys\n", j["camera_keys"].get<std::size_t>());
  std::printf("memory      %.1f MiB\n", double(j["memory_bytes"].get<std::size_t>()) / (1024.0 * 1024.0));
  std::printf("loaded in   %.3f s\n", j["load_s"].get<double>());
  if (!j.contains("scene")) return;
  const auto& s = j["scene"];
  std::printf("scene       %zu objects, %u distinct sources, %u keyframes at %g fps\n", s["objects"].size(),
              s["distinct_sources"].get<unsigned>(), j["frames"].get<unsigned>(), s["fps"].get<double>());
  std::printf("  %-16s %9s %8s %12s %12s %6s  %s\n", "object", "instances", "subdiv", "triangles", "moving verts",
              "keys", "file");
  for (const auto& o : s["objects"])
    std::printf("  %-16s %9u %8u %12llu %12llu %6u  %s\n", o["name"].get<std::string>().c_str(),
                o["instances"].get<unsigned>(), o["subdivide"].get<unsigned>(),
                (unsigned long long)o["triangles"].get<uint64_t>(), (unsigned long long)o["moving_vertices"].get<uint64_t>(),
                o["source_keyframes"].get<unsigned>(), o["file"].get<std::string>().c_str());
  const auto& m = s["statement"];
  std::printf("statement   %.1f MiB baked animation + %.1f MiB sources; peak %.1f MiB of %.1f MiB available\n",
              double(m["animation_bytes"].get<uint64_t>()) / 1048576.0, double(m["source_bytes"].get<uint64_t>()) / 1048576.0,
              double(m["peak_bytes"].get<uint64_t>()) / 1048576.0, double(m["available_bytes"].get<uint64_t>()) / 1048576.0);
}

// The objects of a scene file, their instances and triangles, and the memory statement.
nlohmann::json describeScene(const anim::BakedScene& baked, double fps) {
  nlohmann::json s;
  s["fps"] = fps;
  s["distinct_sources"] = baked.distinctSources;
  s["objects"] = nlohmann::json::array();
  for (const anim::SceneObjectReport& o : baked.objects)
    s["objects"].push_back({{"name", o.name},
                            {"file", o.file},
                            {"instances", o.instances},
                            {"subdivide", o.subdivisionLevels},
                            {"source_triangles", o.sourceTriangles},
                            {"source_keyframes", o.sourceKeyframes},
                            {"triangles", o.triangles},
                            {"vertices", o.vertices},
                            {"moving_vertices", o.movingVertices}});
  const anim::SceneStatement& m = baked.statement;
  s["statement"] = {{"animation_bytes", m.animationBytes}, {"source_bytes", m.sourceBytes},
                    {"peak_bytes", m.peakBytes}, {"available_bytes", m.availableBytes}};
  return s;
}

}  // namespace

TSAH_REGISTER_COMMAND(10, [](CLI::App& app) {
  auto* sub = app.add_subcommand("info", "Print what an input holds (animation or .tbvh file)");
  struct Options {
    std::string input, animation;
    uint32_t frames = 0;
    bool json = false, structure = false;
  };
  auto opt = std::make_shared<Options>();
  sub->add_option("INPUT", opt->input,
                  "Animation (mesh file, directory, 'pattern_%04d.obj', quoted glob, .json manifest, "
                  ".tanim, scene .json) or a .tbvh tree")
      ->required();
  sub->add_option("ANIMATION", opt->animation,
                  "With a .tbvh INPUT: the animation it was built for; prints per-frame quality figures (a two-level "
                  "tree: its scene file; prints the structure and each level's cost and memory)");
  sub->add_option("--frames", opt->frames, "With ANIMATION: this many uniformly spaced frames (default: every keyframe)")
      ->check(CLI::Range(1u, 1000000u));
  sub->add_flag("--json", opt->json, "Print one JSON object");
  sub->add_flag("--structure", opt->structure,
                "With a scene file: what `tsah optimize --structure auto` chooses per object, with the default "
                "tree options (loads the sources, bakes nothing)");
  sub->callback([opt] {
    if (opt->structure) {
      if (!opt->animation.empty() || opt->frames || !anim::isSceneFile(opt->input))
        throw tsah::cli::UsageError("--structure goes with a scene file alone: tsah info SCENE --structure");
      const nlohmann::json j = tsah::cli::describeStructureChoice(
          tsah::cli::chooseStructure(tsah::cli::loadSceneSourcesForCli(opt->input), tsah::TreeOptions{}));
      if (opt->json)
        std::printf("%s\n", j.dump().c_str());
      else
        tsah::cli::printStructureChoice(j);
      return;
    }
    if (tsah::cli::isTwoLevelTreeFile(opt->input)) {  // version 3: read only with its scene
      if (opt->animation.empty())
        throw tsah::cli::UsageError(opt->input + " holds a two-level scene (.tbvh version 3): give its scene too: "
                                    "tsah info TREE SCENE");
      if (opt->frames) throw tsah::cli::UsageError("--frames goes with a flat tree; a two-level tree reports the scene's frames");
      return tsah::cli::describeTwoLevelFile(opt->input, opt->animation, opt->json);
    }
    if (!opt->animation.empty())  // tsah info TREE ANIMATION: the tree over the animation's frames
      return tsah::cli::describeTreeOverAnimation(opt->input, opt->animation, opt->frames, opt->json);
    if (opt->frames) throw tsah::cli::UsageError("--frames needs a tree and its animation: tsah info TREE ANIMATION");
    if (tsah::cli::looksLikeBvhFile(opt->input)) {
      tsah::cli::describeBvhFile(opt->input, opt->json);
      return;
    }
    tsah::cli::Progress timer("info");
    nlohmann::json j;
    if (anim::isSceneFile(opt->input)) {
      anim::LoadOptions load = tsah::cli::commandLineLoadOptions();
      load.resolveDataPath = tsah::cli::dataPathResolver();
      const anim::BakedScene baked = anim::bakeScene(opt->input, load);
      j = describe(baked.animation, timer.elapsedSeconds());
      j["scene"] = describeScene(baked, load.fps > 0.0 ? load.fps : baked.description.fps);
    } else {
      j = describe(tsah::cli::loadInput(opt->input), timer.elapsedSeconds());
    }
    if (opt->json)
      std::printf("%s\n", j.dump().c_str());
    else
      printText(j);
  });
});
