// tsah resample INPUT -o OUT.tanim|OUT.pc2|OUT.mdd [--frames N] [--range START:END] [--no-mesh]
#include <cstdint>
#include <cstdio>
#include <filesystem>

#include "anim/obj_writer.hpp"
#include "anim/point_cache.hpp"
#include "anim/tanim.hpp"
#include "cli.hpp"
#include "scale_out.hpp"
#include "tsah/base/files.hpp"
#include "tsah/base/memory.hpp"

namespace {

// A point cache holds positions only: its topology goes next to it as OUT.obj (the first keyframe's
// positions, the animation's point order), unless that file is the input's own mesh, which already
// has this topology and is left untouched. The two are one output set: both appear or neither.
std::string writeTopology(const anim::Animation& a, const std::string& cachePath, const std::string& input,
                          tsah::AtomicFileSet& files) {
  namespace fs = std::filesystem;
  const std::string mesh = fs::path(cachePath).replace_extension(".obj").string();
  std::error_code ec;
  if (const auto pair = anim::splitPointCacheInput(input); pair && fs::equivalent(mesh, pair->mesh, ec))
    return mesh + " (the input's mesh, kept)";
  anim::saveObjFrame(a, 0, mesh, files);
  return mesh;
}

// The whole request, stated before anything is resampled: the resampled animation and its file as
// encoded in memory (.tanim: the payload and the file, each about the animation's size; a point
// cache: every position gathered once and encoded once, and the topology OBJ's text).
std::size_t resampleBytes(const anim::Animation& in, uint32_t frames, const std::string& output, bool mesh) {
  __extension__ typedef unsigned __int128 Wide;
  const uint64_t keyframes = frames ? frames : in.keyframeCount();
  const Wide animation = anim::Animation::memoryBytesFor(in.triangleCount(), in.vertexCount(), in.movingVertexCount(), keyframes);
  Wide file = 2 * animation;
  if (anim::pointCacheFormat(output))
    file = 2 * Wide(keyframes) * in.vertexCount() * 12 + (mesh ? (Wide(in.vertexCount()) + in.triangleCount()) * 64 : 0);
  const Wide total = animation + file;
  return total > SIZE_MAX ? SIZE_MAX : std::size_t(total);
}

}  // namespace

TSAH_REGISTER_COMMAND(30, [](CLI::App& app) {
  auto* sub = app.add_subcommand(
      "resample", "Resample an animation into N uniformly spaced frames (.tanim, or a .pc2/.mdd point cache)");
  struct Options {
    std::string input, output;
    uint32_t frames = 0;
    std::string range;  // START:END over the output's keyframes, half-open
    bool noMesh = false;
  };
  auto opt = std::make_shared<Options>();
  sub->add_option("INPUT", opt->input, "Any animation input")->required();
  sub->add_option("-o,--output", opt->output,
                  "Output: .tanim, or a point cache .pc2 / .mdd (with its topology as OUT.obj)")
      ->required();
  sub->add_option("--frames", opt->frames, "Uniformly spaced frames over the time range (default: keep every keyframe)")
      ->check(CLI::Range(1u, anim::Animation::kMaxResampleFrames));
  sub->add_option("--range", opt->range,
                  "START:END: only the output keyframes START .. END-1 (half-open), at their times in the whole output");
  sub->add_flag("--no-mesh", opt->noMesh, "With a .pc2/.mdd output: do not write the topology OBJ next to it");
  sub->callback([opt] {
    const anim::Animation input = tsah::cli::loadInput(opt->input);
    tsah::checkFitsInMemory(resampleBytes(input, opt->frames, opt->output, !opt->noMesh), input.name(),
                            std::to_string(opt->frames ? opt->frames : input.keyframeCount()) + " frames");
    const anim::Animation whole = opt->frames ? input.resample(opt->frames) : input;
    const auto [first, end] = tsah::cli::parseFrameRange(opt->range, whole.keyframeCount());
    const anim::Animation out =
        opt->range.empty() ? whole : whole.segment(whole.times()[first], whole.times()[end - 1]);
    std::string extra;
    if (anim::pointCacheFormat(opt->output)) {
      tsah::AtomicFileSet files;
      anim::savePointCache(out, opt->output, files);
      if (!opt->noMesh) extra = " + topology " + writeTopology(out, opt->output, opt->input, files);
      files.commit();
    } else {
      anim::saveTanim(out, opt->output);
    }
    std::printf("%s: %u keyframes (from %u), %u triangles, time %g .. %g%s\n", opt->output.c_str(),
                out.keyframeCount(), input.keyframeCount(), out.triangleCount(), out.startTime(), out.endTime(),
                extra.c_str());
  });
});
