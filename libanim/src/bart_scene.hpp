#pragma once
// Internal to the BART importer: the parsed scene graph (bart_parse.cpp builds it, bart.cpp samples
// it into keyframes).
#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "anim/bart.hpp"

namespace anim::bart_detail {

// Row-major 3x4 affine transform: rows (m[0..3], m[4..7], m[8..11]), last column the translation.
using Affine = std::array<double, 12>;
constexpr Affine kIdentity{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};

// Triangles in the local frame of the block that holds them (meshes, polygons, tessellated shapes).
struct Geometry {
  std::vector<float> positions;   // 3 per vertex
  std::vector<uint32_t> indices;  // 3 per triangle
  uint32_t vertexCount() const { return static_cast<uint32_t>(positions.size() / 3); }
};

// A `tpa` triangle: key shapes at increasing times, linearly interpolated and clamped at the ends.
struct AnimatedTriangle {
  std::vector<double> times;
  std::vector<float> corners;  // 9 per key shape
};

struct FileScene;

// A `{ ... }` scope: the root of a file, a static transform or an animated transform.
struct Block {
  enum class Kind { Group, Static, Animated };
  Kind kind = Kind::Group;
  Affine matrix = kIdentity;  // Static only
  std::string name;           // Animated only: the `k` block that drives it
  std::string file;           // where it opened, for messages
  uint32_t line = 0;

  Geometry geometry;
  std::vector<AnimatedTriangle> animated;
  struct Child {
    std::unique_ptr<Block> block;             // a nested transform, or
    std::shared_ptr<const FileScene> include;  // an included file (shared by every include of it)
  };
  std::vector<Child> children;

  // Totals over the subtree with every include expanded, saturating (set when the block closes).
  uint64_t totalVertices = 0, totalTriangles = 0, totalBlocks = 0;
};

struct FileScene {
  std::string path;
  Block root;
};

struct KeyBlock {
  std::string name, file;
  uint32_t line = 0;
  std::optional<bart::PositionSpline> translation, scale;
  std::optional<bart::RotationSpline> rotation;
  std::vector<std::pair<double, bool>> visibility;  // (time, visible) in file order
};

struct View {
  std::array<double, 3> from{0, 0, 0}, at{0, 0, -1}, up{0, 1, 0};
  double angle = 45.0;
};

struct AnimationRange {
  double t0 = 0.0, t1 = 0.0;
  int64_t frames = 1;
  std::string file;
  uint32_t line = 0;
};

struct ParsedScene {
  std::shared_ptr<const FileScene> root;
  std::map<std::string, KeyBlock> keys;  // by name; a later block of the same name replaces it
  std::optional<AnimationRange> range;
  std::optional<View> view;
  // Things a geometry importer leaves out, reported in one summary warning.
  uint64_t materials = 0, lights = 0, textures = 0, backgrounds = 0;
  std::vector<std::string> warnings;
};

// Parses `text` as the file `path` and every file it includes. Throws tsah::FileError naming file:line.
ParsedScene parseScene(std::string_view text, const std::string& path, const BartOptions& options);

}  // namespace anim::bart_detail
