#include "anim/obj_writer.hpp"

#include <cstdio>
#include <filesystem>
#include <string>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "frame_pattern.hpp"

namespace anim {

namespace {

std::string faceLines(const Animation& a) {
  std::string faces;
  const auto idx = a.indices();
  char line[128];
  for (std::size_t t = 0; t < idx.size(); t += 3) {
    std::snprintf(line, sizeof line, "f %u %u %u\n", idx[t] + 1, idx[t + 1] + 1, idx[t + 2] + 1);
    faces += line;
  }
  return faces;
}

// One keyframe as OBJ text: a comment, the vertices (every float exactly: %.9g) and the faces.
std::string objText(const Animation& a, uint32_t k, const std::string& faces) {
  std::string text = "# " + a.name() + " keyframe " + std::to_string(k) + " time " + std::to_string(a.times()[k]) + "\n";
  const auto p = a.keyframe(k);
  char line[128];
  for (std::size_t v = 0; v < p.size(); v += 3) {
    std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", double(p[v]), double(p[v + 1]), double(p[v + 2]));
    text += line;
  }
  return text + faces;
}

std::span<const uint8_t> bytesOf(const std::string& text) {
  return {reinterpret_cast<const uint8_t*>(text.data()), text.size()};
}

std::string frameText(const Animation& a, uint32_t keyframe, const std::string& path) {
  if (keyframe >= a.keyframeCount())
    throw tsah::ConfigError(path + ": keyframe " + std::to_string(keyframe) + " is out of range (" +
                            std::to_string(a.keyframeCount()) + " keyframes)");
  return objText(a, keyframe, faceLines(a));
}

}  // namespace

std::size_t saveObjSequence(const Animation& a, const std::string& pattern) {
  const detail::FramePatternParse parsed = detail::parseFramePattern(pattern);
  if (!parsed.pattern)
    throw tsah::ConfigError(pattern + ": output pattern needs exactly one %d-style number, e.g. frames/f_%04d.obj");
  tsah::requireExtension(pattern, ".obj", "OBJ sequence");
  const std::string faces = faceLines(a);
  // All frames appear together or none: a failure half-way (a full disk) must not leave a shorter
  // sequence behind that reads as a valid animation.
  tsah::AtomicFileSet files;
  for (uint32_t k = 0; k < a.keyframeCount(); ++k) {
    const std::string name = parsed.pattern->format(k + 1);
    if (k == 0) {
      const auto parent = std::filesystem::path(name).parent_path();
      std::error_code ec;
      if (!parent.empty()) std::filesystem::create_directories(parent, ec);
    }
    const std::string text = objText(a, k, faces);
    files.write(name, bytesOf(text));
  }
  files.commit();
  return a.keyframeCount();
}

void saveObjFrame(const Animation& a, uint32_t keyframe, const std::string& path) {
  tsah::writeFileAtomically(path, bytesOf(frameText(a, keyframe, path)));
}

void saveObjFrame(const Animation& a, uint32_t keyframe, const std::string& path, tsah::AtomicFileSet& set) {
  set.write(path, bytesOf(frameText(a, keyframe, path)));
}

}  // namespace anim
