// Pairing a point cache with the mesh that gives its topology: "mesh.obj+cache.pc2" inputs,
// {"mesh": ..., "cache": ...} manifests, and the import itself.
#include <filesystem>
#include <nlohmann/json.hpp>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "anim/mesh_sequence.hpp"
#include "anim/point_cache.hpp"

namespace anim {

namespace fs = std::filesystem;

std::optional<PointCacheInput> splitPointCacheInput(const std::string& input) {
  for (std::size_t plus = input.find('+'); plus != std::string::npos; plus = input.find('+', plus + 1)) {
    std::string mesh = input.substr(0, plus), cache = input.substr(plus + 1);
    if (isMeshFile(mesh) && pointCacheFormat(cache)) return PointCacheInput{std::move(mesh), std::move(cache)};
  }
  return std::nullopt;
}

std::optional<PointCacheInput> readPointCacheManifest(const std::string& path) {
  const std::vector<uint8_t> bytes = tsah::readFile(path, std::size_t(1) << 28);
  const nlohmann::json doc = nlohmann::json::parse(bytes.begin(), bytes.end(), nullptr, false);
  if (!doc.is_object() || !doc.contains("cache")) return std::nullopt;  // another kind of manifest
  if (!doc["cache"].is_string() || !doc.contains("mesh") || !doc["mesh"].is_string())
    throw tsah::FileError(path, "a point-cache manifest needs \"mesh\" and \"cache\" file names: "
                            "{\"mesh\": \"horse.obj\", \"cache\": \"horse.mdd\"}");
  const fs::path base = fs::path(path).parent_path();
  auto resolve = [&](const std::string& name) {
    const fs::path p(name);
    return p.is_absolute() ? p.string() : (base / p).string();
  };
  PointCacheInput pair{resolve(doc["mesh"].get<std::string>()), resolve(doc["cache"].get<std::string>())};
  if (!pointCacheFormat(pair.cache)) throw tsah::FileError(path, "\"cache\" must name a .pc2 or .mdd file");
  return pair;
}

Animation importPointCache(const PointCacheInput& input, const LoadOptions& options) {
  const auto format = pointCacheFormat(input.cache);
  if (!format) throw tsah::FileError(input.cache, "not a point cache (expected .pc2 or .mdd)");
  MeshFrame mesh = readMesh(input.mesh);
  if (mesh.indices.empty()) throw tsah::FileError(input.mesh, "has no faces");
  PointCache cache = decodePointCache(tsah::readFile(input.cache), input.cache, *format);
  const uint32_t meshPoints = uint32_t(mesh.positions.size() / 3);
  if (cache.pointCount != meshPoints)
    throw tsah::FileError(input.cache, "holds " + std::to_string(cache.pointCount) + " points but the mesh " + input.mesh +
                                       " has " + std::to_string(meshPoints) +
                                       " vertices (the cache needs a mesh with the same points in the same order)");
  if (cache.skippedRestFrame && options.warning)
    options.warning(input.cache + ": skipped the rest-pose block Blender writes before the frames");
  return Animation(std::move(mesh.indices), meshPoints, std::move(cache.positions), std::move(cache.times),
                   fs::path(input.cache).stem().string());
}

}  // namespace anim
