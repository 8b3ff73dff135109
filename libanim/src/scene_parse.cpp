// Reading a scene file (docs/scenes.md) into a SceneDescription, and the transform arithmetic.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "anim/point_cache.hpp"
#include "anim/scene.hpp"

namespace anim {

Matrix4 identityMatrix() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

Matrix4 multiply(const Matrix4& a, const Matrix4& b) {
  Matrix4 r{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 4; ++k) r[4 * i + j] += a[4 * i + k] * b[4 * k + j];
  return r;
}

Matrix4 trsMatrix(const std::array<double, 3>& translate, const std::array<double, 3>& rotateDegrees,
                  const std::array<double, 3>& scale) {
  const double kRad = 3.14159265358979323846 / 180.0;
  const double cx = std::cos(rotateDegrees[0] * kRad), sx = std::sin(rotateDegrees[0] * kRad);
  const double cy = std::cos(rotateDegrees[1] * kRad), sy = std::sin(rotateDegrees[1] * kRad);
  const double cz = std::cos(rotateDegrees[2] * kRad), sz = std::sin(rotateDegrees[2] * kRad);
  const Matrix4 rx{1, 0, 0, 0, 0, cx, -sx, 0, 0, sx, cx, 0, 0, 0, 0, 1};
  const Matrix4 ry{cy, 0, sy, 0, 0, 1, 0, 0, -sy, 0, cy, 0, 0, 0, 0, 1};
  const Matrix4 rz{cz, -sz, 0, 0, sz, cz, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  const Matrix4 s{scale[0], 0, 0, 0, 0, scale[1], 0, 0, 0, 0, scale[2], 0, 0, 0, 0, 1};
  const Matrix4 t{1, 0, 0, translate[0], 0, 1, 0, translate[1], 0, 0, 1, translate[2], 0, 0, 0, 1};
  return multiply(t, multiply(rz, multiply(ry, multiply(rx, s))));
}

double linearDeterminant(const Matrix4& m) {
  return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
         m[2] * (m[4] * m[9] - m[5] * m[8]);
}

void transformPoints(const Matrix4& m, float* points, std::size_t count) {
  for (std::size_t i = 0; i < count; ++i) {
    float* p = points + 3 * i;
    const double x = p[0], y = p[1], z = p[2];
    for (int r = 0; r < 3; ++r) p[r] = float(m[4 * r] * x + m[4 * r + 1] * y + m[4 * r + 2] * z + m[4 * r + 3]);
  }
}

Matrix4 pathMatrix(const std::vector<TransformKey>& path, double t) {
  if (path.empty()) return identityMatrix();
  auto matrixOf = [](const TransformKey& k) { return trsMatrix(k.translate, k.rotateDegrees, k.scale); };
  if (path.size() == 1 || t <= path.front().time) return matrixOf(path.front());
  if (t >= path.back().time) return matrixOf(path.back());
  const auto next = std::upper_bound(path.begin(), path.end(), t,
                                     [](double time, const TransformKey& k) { return time < k.time; });
  const TransformKey &a = *(next - 1), &b = *next;
  const double w = (t - a.time) / (b.time - a.time);
  TransformKey mix;
  for (int i = 0; i < 3; ++i) {
    mix.translate[i] = a.translate[i] + w * (b.translate[i] - a.translate[i]);
    mix.rotateDegrees[i] = a.rotateDegrees[i] + w * (b.rotateDegrees[i] - a.rotateDegrees[i]);
    mix.scale[i] = a.scale[i] + w * (b.scale[i] - a.scale[i]);
  }
  return matrixOf(mix);
}

double TimeMapping::localTime(double sceneTime, double start, double end) const {
  const double local = start + (sceneTime - offset) * speed;
  const double length = end - start;
  if (outside == OutsideRange::Hold || !(length > 0.0)) return std::clamp(local, start, end);
  double wrapped = std::fmod(local - start, length);
  if (wrapped < 0.0) wrapped += length;
  return start + wrapped;
}

void checkDataPath(const std::string& rel) {
  const std::filesystem::path p(rel);
  const bool climbs = std::any_of(p.begin(), p.end(), [](const std::filesystem::path& part) { return part == ".."; });
  if (rel.empty() || p.is_absolute() || climbs)
    throw tsah::DataError("\"data:" + rel + "\" must name a path inside the data folder (relative, without \"..\")");
}

void requireInsideDataFolder(const std::filesystem::path& folder, const std::filesystem::path& path,
                             const std::string& rel) {
  std::error_code ec;
  const auto root = std::filesystem::weakly_canonical(folder, ec);
  const auto target = std::filesystem::weakly_canonical(path, ec);
  if (ec) throw tsah::DataError("\"data:" + rel + "\" cannot be resolved (" + ec.message() + ")");
  // Inside: the folder's parts are a prefix of the target's.
  const auto [rootEnd, targetAt] = std::mismatch(root.begin(), root.end(), target.begin(), target.end());
  if (rootEnd != root.end() && !(std::next(rootEnd) == root.end() && rootEnd->empty()))
    throw tsah::DataError("\"data:" + rel + "\" leads to " + target.string() +
                          ", outside the data folder (through a symbolic link)");
}

namespace {

using nlohmann::json;

constexpr std::size_t kMaxSceneFileBytes = std::size_t(64) << 20;

// Every error of a scene file names the file (tsah::FileError) and, where one is at fault, the object.
struct Context {
  std::string file;
  std::string object;  // empty at scene level
  [[noreturn]] void fail(const std::string& what) const {
    throw tsah::FileError(file, object.empty() ? what : "object '" + tsah::printable(object) + "': " + what);
  }
};

double number(const json& j, const char* key, const Context& at) {
  if (!j.is_number()) at.fail(std::string("\"") + key + "\" must be a number");
  const double v = j.get<double>();
  if (!std::isfinite(v)) at.fail(std::string("\"") + key + "\" is not finite");
  return v;
}

std::array<double, 3> triple(const json& j, const char* key, const Context& at, bool uniformAllowed) {
  if (uniformAllowed && j.is_number()) {
    const double v = number(j, key, at);
    return {v, v, v};
  }
  if (!j.is_array() || j.size() != 3) at.fail(std::string("\"") + key + "\" must be an array of 3 numbers");
  return {number(j[0], key, at), number(j[1], key, at), number(j[2], key, at)};
}

void checkInvertible(const Matrix4& m, const Context& at, const std::string& what) {
  for (double v : m)
    if (!std::isfinite(v)) at.fail(what + " has a NaN or infinite entry");
  double largest = 0.0;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) largest = std::max(largest, std::abs(m[4 * r + c]));
  const double det = linearDeterminant(m);
  if (!std::isfinite(det)) at.fail(what + " has an infinite determinant (its scale overflows)");
  if (!(std::abs(det) > 1e-12 * largest * largest * largest)) at.fail(what + " is not invertible (determinant " +
                                                                        std::to_string(det) + ")");
}

TransformKey trsOf(const json& j, const Context& at) {
  TransformKey k;
  for (const auto& [key, value] : j.items()) {
    if (key == "translate") k.translate = triple(value, "translate", at, false);
    else if (key == "rotate") k.rotateDegrees = triple(value, "rotate", at, false);
    else if (key == "scale") k.scale = triple(value, "scale", at, true);
    else if (key == "time") k.time = number(value, "time", at);
    else if (key != "matrix") at.fail("unknown transform field \"" + key + "\"");
  }
  return k;
}

Matrix4 placementOf(const json& j, const Context& at) {
  if (!j.is_object()) at.fail("\"transform\" must be an object");
  Matrix4 m;
  if (j.contains("matrix")) {
    if (j.contains("translate") || j.contains("rotate") || j.contains("scale"))
      at.fail("\"transform\" has both \"matrix\" and translate/rotate/scale");
    const json& a = j["matrix"];
    if (!a.is_array() || a.size() != 16) at.fail("\"matrix\" must be an array of 16 numbers (row-major)");
    for (int i = 0; i < 16; ++i) {
      if (!a[i].is_number()) at.fail("\"matrix\" must be an array of 16 numbers (row-major)");
      m[i] = a[i].get<double>();
    }
    for (double v : m)
      if (!std::isfinite(v)) at.fail("\"matrix\" has a NaN or infinite entry");
    if (m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || m[15] != 1.0)
      at.fail("\"matrix\" is not affine (its last row must be 0 0 0 1)");
  } else {
    if (j.contains("time")) at.fail("\"transform\" takes no \"time\" (keys go in \"path\")");
    const TransformKey k = trsOf(j, at);
    m = trsMatrix(k.translate, k.rotateDegrees, k.scale);
  }
  checkInvertible(m, at, "the transform");
  return m;
}

std::vector<TransformKey> pathOf(const json& j, const Context& at) {
  if (!j.is_array()) at.fail("\"path\" must be an array of keys");
  std::vector<TransformKey> path;
  for (const json& key : j) {
    if (!key.is_object() || !key.contains("time")) at.fail("every \"path\" key needs a \"time\"");
    if (key.contains("matrix")) at.fail("\"path\" keys take translate/rotate/scale, not a matrix");
    path.push_back(trsOf(key, at));
    if (path.size() > 1 && !(path.back().time > path[path.size() - 2].time))
      at.fail("\"path\" key times are not strictly increasing");
    const auto& s = path.back().scale;
    if (s[0] == 0.0 || s[1] == 0.0 || s[2] == 0.0)
      at.fail("a \"path\" key at time " + std::to_string(path.back().time) + " has a zero scale (not invertible)");
  }
  return path;
}

TimeMapping timeOf(const json& j, TimeMapping mapping, const Context& at) {
  if (!j.is_object()) at.fail("\"time\" must be an object");
  for (const auto& [key, value] : j.items()) {
    if (key == "offset") mapping.offset = number(value, "offset", at);
    else if (key == "speed") mapping.speed = number(value, "speed", at);
    else if (key == "outside") {
      const std::string o = value.is_string() ? value.get<std::string>() : "";
      if (o == "hold") mapping.outside = OutsideRange::Hold;
      else if (o == "loop") mapping.outside = OutsideRange::Loop;
      else at.fail("\"outside\" must be \"hold\" or \"loop\"");
    } else at.fail("unknown time field \"" + key + "\"");
  }
  if (mapping.speed < 0.0) at.fail("negative speed " + std::to_string(mapping.speed) + " (play speeds are >= 0)");
  return mapping;
}

// One placement from the fields of an object or of one of its instances, on top of `base`.
SceneInstance instanceOf(const json& j, SceneInstance base, const Context& at) {
  if (j.contains("transform")) base.placement = placementOf(j["transform"], at);
  if (j.contains("path")) base.path = pathOf(j["path"], at);
  if (j.contains("time")) base.time = timeOf(j["time"], base.time, at);
  if (j.contains("offset")) {
    // "offset" is short for "time": {"offset": ...}; both at once would silently drop one of them.
    if (j.contains("time") && j["time"].is_object() && j["time"].contains("offset"))
      at.fail("both \"offset\" and \"time\": {\"offset\"} are given; keep one");
    base.time.offset = number(j["offset"], "offset", at);
  }
  return base;
}

// One input of an object: "data:REL" inside the data folder, else relative to the scene's folder.
std::string resolveOne(const std::string& file, const std::filesystem::path& sceneFolder, const LoadOptions& options,
                       const Context& at) {
  if (file.rfind("data:", 0) != 0) {
    const std::filesystem::path p(file);
    return p.is_absolute() ? file : (sceneFolder / p).lexically_normal().string();
  }
  const std::string rel = file.substr(5);
  try {
    checkDataPath(rel);
    if (options.resolveDataPath) return options.resolveDataPath(rel);
    const char* env = std::getenv("TSAH_DATA_DIR");
    if (!env || !*env) at.fail("\"" + file + "\" needs the data folder (set TSAH_DATA_DIR)");
    const std::filesystem::path resolved = std::filesystem::path(env) / rel;
    requireInsideDataFolder(env, resolved, rel);
    return resolved.string();
  } catch (const tsah::FileError&) {
    throw;
  } catch (const tsah::DataError& e) {
    at.fail(e.what());
  }
}

// The object's "file": MESH+CACHE resolves each half on its own, so that the cache, like the mesh,
// is found beside the scene file.
std::string resolveFile(const std::string& file, const std::filesystem::path& sceneFolder, const LoadOptions& options,
                        const Context& at) {
  if (file.empty()) at.fail("\"file\" is empty (name an input, relative to the scene file's folder)");
  if (const auto pair = splitPointCacheInput(file))
    return resolveOne(pair->mesh, sceneFolder, options, at) + "+" + resolveOne(pair->cache, sceneFolder, options, at);
  return resolveOne(file, sceneFolder, options, at);
}

SceneObject objectOf(const json& j, std::size_t index, const std::filesystem::path& folder, const LoadOptions& options,
                     const Context& scene) {
  Context at{scene.file, std::string("number ").append(std::to_string(index + 1))};
  if (!j.is_object()) at.fail("must be an object");
  SceneObject o;
  if (j.contains("name")) {
    if (!j["name"].is_string()) at.fail("\"name\" must be a string");
    o.name = j["name"].get<std::string>();
  }
  if (!j.contains("file") || !j["file"].is_string()) at.fail("needs a \"file\" (any input the toolkit reads)");
  const std::string file = j["file"].get<std::string>();
  if (o.name.empty()) o.name = std::filesystem::path(file).stem().string();
  at.object = o.name;
  static const char* kKnown[] = {"name", "file", "fps", "clip", "subdivide", "transform", "path", "time", "offset",
                                 "instances"};
  for (const auto& [key, value] : j.items())
    if (std::find(std::begin(kKnown), std::end(kKnown), key) == std::end(kKnown)) at.fail("unknown field \"" + key + "\"");
  o.file = resolveFile(file, folder, options, at);
  if (j.contains("fps")) {
    o.fps = number(j["fps"], "fps", at);
    if (!(o.fps > 0.0)) at.fail("\"fps\" must be positive");
  }
  if (j.contains("clip")) o.clip = j["clip"].is_string() ? j["clip"].get<std::string>() : j["clip"].dump();
  if (j.contains("subdivide")) {
    if (!j["subdivide"].is_number_integer() || j["subdivide"].get<int64_t>() < 0 || j["subdivide"].get<int64_t>() > 16)
      at.fail("\"subdivide\" must be a whole number of levels, 0..16");
    o.subdivide = j["subdivide"].get<uint32_t>();
  }
  const SceneInstance defaults = instanceOf(j, SceneInstance{}, at);
  if (j.contains("instances")) {
    const json& list = j["instances"];
    if (!list.is_array() || list.empty()) at.fail("\"instances\" must be a non-empty array");
    for (const json& i : list) {
      if (!i.is_object()) at.fail("every instance must be an object");
      for (const auto& [key, value] : i.items())
        if (key != "transform" && key != "path" && key != "time" && key != "offset")
          at.fail("unknown instance field \"" + key + "\"");
      o.instances.push_back(instanceOf(i, defaults, at));
    }
  } else {
    o.instances.push_back(defaults);
  }
  return o;
}

json readJson(const std::string& path) {
  const std::vector<uint8_t> bytes = tsah::readFile(path, kMaxSceneFileBytes);
  try {
    return json::parse(bytes.begin(), bytes.end());
  } catch (const json::exception& e) {
    throw tsah::FileError(path, std::string("not valid JSON (") + e.what() + ")");
  }
}

}  // namespace

bool isSceneFile(const std::string& path) {
  std::vector<uint8_t> bytes;
  try {
    bytes = tsah::readFile(path, kMaxSceneFileBytes);
  } catch (const tsah::Error&) {
    return false;  // the manifest reader reports what is wrong with it
  }
  const json j = json::parse(bytes.begin(), bytes.end(), nullptr, false);
  if (!j.is_discarded()) return j.is_object() && j.contains("objects");
  // Not valid JSON: a scene when it mentions "objects", so the error comes from the scene reader.
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  return text.find("\"objects\"") != std::string_view::npos;
}

SceneDescription parseScene(const std::string& path, const LoadOptions& options) {
  const Context at{path, {}};
  const json j = readJson(path);
  if (!j.is_object() || !j.contains("objects")) at.fail("not a scene file (no \"objects\")");
  SceneDescription scene;
  scene.file = path;
  scene.name = std::filesystem::path(path).stem().string();
  for (const auto& [key, value] : j.items()) {
    if (key == "name") {
      if (!value.is_string()) at.fail("\"name\" must be a string");
      scene.name = value.get<std::string>();
    } else if (key == "fps") {
      scene.fps = number(value, "fps", at);
      if (!(scene.fps > 0.0)) at.fail("\"fps\" must be positive");
    } else if (key == "time") {
      if (!value.is_array() || value.size() != 2) at.fail("\"time\" must be [start, end]");
      scene.start = number(value[0], "time", at);
      scene.end = number(value[1], "time", at);
      if (scene.end < scene.start) at.fail("\"time\" ends before it starts");
      scene.hasTimeRange = true;
    } else if (key != "objects") {
      at.fail("unknown field \"" + key + "\"");
    }
  }
  const json& objects = j["objects"];
  if (!objects.is_array() || objects.empty()) at.fail("\"objects\" must be a non-empty array");
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  for (std::size_t i = 0; i < objects.size(); ++i) scene.objects.push_back(objectOf(objects[i], i, folder, options, at));
  return scene;
}

}  // namespace anim
