#include "anim/load.hpp"

#include <algorithm>
#include <filesystem>
#include <system_error>

#include "anim/assimp_import.hpp"
#include "anim/bart.hpp"
#include "tsah/base/error.hpp"
#include "anim/mesh_sequence.hpp"
#include "anim/point_cache.hpp"
#include "anim/scene.hpp"
#include "anim/tanim.hpp"

namespace anim {

namespace {

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

std::string stemName(const std::string& input) {
  std::filesystem::path p(input);
  if (p.filename().empty()) p = p.parent_path();
  return p.stem().string();
}

}  // namespace

Animation load(const std::string& input, const LoadOptions& options) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (input.empty()) throw tsah::FileError("<input>", "empty input path");
  if (!(options.fps >= 0.0 && options.fps <= LoadOptions::kMaxFps))  // NaN fails too
    throw tsah::ConfigError("fps: must be in [0, " + std::to_string(int(LoadOptions::kMaxFps)) +
                            "] (0: the input's own frames), not " + std::to_string(options.fps));
  if (input.find('%') != std::string::npos || input.find_first_of("*?[") != std::string::npos)
    return importSequence(listFrames(input), options, stemName(fs::path(input).parent_path().string()));
  if (fs::is_directory(input, ec)) return importSequence(listFrames(input), options, stemName(input));
  if (const auto pair = splitPointCacheInput(input)) return importPointCache(*pair, options);  // mesh.obj+cache.pc2
  if (!fs::exists(input, ec)) throw tsah::FileError(input, "no such file or directory");
  const std::string ext = lowerExtension(input);
  if (ext == ".tanim") return loadTanim(input);
  if (ext == ".aff") {
    BartOptions bart;
    bart.fps = options.fps;
    bart.warning = options.warning;
    bart.progress = options.progress;
    return importBart(input, bart);
  }
  if (isModelFile(input)) return importModel(input, options);
  if (pointCacheFormat(input))
    throw tsah::FileError(input, "a point cache holds positions only: name a mesh of the same points with it, as "
                             "mesh.obj+" + fs::path(input).filename().string());
  if (ext == ".json" && isSceneFile(input)) return loadScene(input, options);
  if (ext == ".json") {
    if (const auto pair = readPointCacheManifest(input)) return importPointCache(*pair, options);
    return importSequence(readManifest(input), options, stemName(input));
  }
  if (isMeshFile(input)) return importSequence(FrameList{{input}, {}}, options, stemName(input));
  throw tsah::FileError(input, "unknown input format '" + ext +
                               "' (expected .tanim, .json manifest, a mesh file, a directory, a "
                               "printf pattern or a glob)");
}

}  // namespace anim
