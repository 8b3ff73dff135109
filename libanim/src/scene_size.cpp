// A scene's size from its description (declared in anim/scene.hpp): nested scene files are counted
// from their own descriptions, never baked, so a chain of scenes that doubles at every level is
// measured in one pass.
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <limits>
#include <map>

#include "anim/load.hpp"
#include "anim/scene.hpp"
#include "anim/subdivide.hpp"
#include "tsah/base/error.hpp"

namespace anim {

namespace {

__extension__ typedef unsigned __int128 Wide;

uint64_t saturated(Wide n) {
  return n > std::numeric_limits<uint64_t>::max() ? std::numeric_limits<uint64_t>::max() : uint64_t(n);
}

bool namesSceneFile(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext == ".json" && isSceneFile(path);
}

std::string canonical(const std::string& path) {
  std::error_code ec;
  const auto c = std::filesystem::weakly_canonical(path, ec);
  return ec ? path : c.string();
}

// One pass over a tree of scene files: each (file, options) counted once, however often it is used.
class Describer {
 public:
  SceneSize scene(const std::string& path, const LoadOptions& options) {
    const SceneDescription description = parseScene(path, options);
    SceneSize total;
    for (const SceneObject& object : description.objects) {
      const SceneSize one = this->object(object, options);
      const Wide instances = object.instances.size();
      total.triangles = saturated(Wide(total.triangles) + Wide(one.triangles) * instances);
      total.vertices = saturated(Wide(total.vertices) + Wide(one.vertices) * instances);
    }
    return total;
  }

 private:
  SceneSize object(const SceneObject& object, const LoadOptions& options) {
    LoadOptions own = options;
    own.fps = object.fps > 0.0 ? object.fps : options.fps;
    own.clip = object.clip;
    own.progress = nullptr;
    const std::string file = canonical(object.file);
    const std::string key = file + "\n" + std::to_string(own.fps) + "\n" + own.clip + "\n" + std::to_string(object.subdivide);
    if (const auto it = done_.find(key); it != done_.end()) return it->second;
    // A cycle, or a file that cannot be read: counted as empty here; the bake reports it with its
    // scene and object.
    if (std::find(stack_.begin(), stack_.end(), file) != stack_.end()) return {};
    MeshCounts counts;
    const std::size_t depth = stack_.size();
    try {
      if (namesSceneFile(object.file)) {
        stack_.push_back(file);
        const SceneSize nested = scene(object.file, own);
        stack_.pop_back();
        counts = {nested.vertices, saturated(Wide(nested.triangles) * 3 / 2), nested.triangles};  // closed-mesh edges
      } else {
        const Animation a = load(object.file, own);
        counts = object.subdivide > 0 ? meshCounts(a) : MeshCounts{a.vertexCount(), 0, a.triangleCount()};
      }
    } catch (const tsah::Error&) {
      stack_.resize(depth);
      return {};
    }
    // Loop levels as loopSubdividedCounts counts them, saturated: 16 levels of a large scene overflow.
    for (uint32_t level = 0; level < object.subdivide; ++level)
      counts = {saturated(Wide(counts.vertices) + counts.edges), saturated(Wide(counts.edges) * 2 + Wide(counts.triangles) * 3),
                saturated(Wide(counts.triangles) * 4)};
    return done_[key] = SceneSize{counts.triangles, counts.vertices};
  }

  std::map<std::string, SceneSize> done_;
  std::vector<std::string> stack_;
};

}  // namespace

SceneSize describedSceneSize(const std::string& path, const LoadOptions& options) {
  Describer describer;
  return describer.scene(path, options);
}

}  // namespace anim
