#pragma once
// The options every importer takes (load.hpp is the front door that picks the importer).
#include <cstddef>
#include <functional>
#include <string>

namespace anim {

struct LoadOptions {
  // Sampling rate for formats that store continuous animation (AFF, skeletal, morph targets);
  // 0 means the format's own frame rate / frame count. At most kMaxFps (the command line's --fps
  // limit); load() refuses a value outside [0, kMaxFps] with tsah::ConfigError.
  double fps = 0.0;
  static constexpr double kMaxFps = 10000.0;
  // Which animation clip to bake when a file holds several (name or index); empty: the first.
  std::string clip;
  // Called as work progresses (done, total); may be empty. Libraries never print.
  std::function<void(std::size_t done, std::size_t total)> progress;
  // Called with each non-fatal finding of an importer (skipped materials, ...); may be empty.
  std::function<void(const std::string&)> warning;
  // Resolves a scene object's "data:REL" path (docs/scenes.md); empty: $TSAH_DATA_DIR/REL.
  std::function<std::string(const std::string& rel)> resolveDataPath;
};

}  // namespace anim
