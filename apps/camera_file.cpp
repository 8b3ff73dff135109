#include "camera_file.hpp"

#include <cmath>
#include <nlohmann/json.hpp>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "tsah/render/camera.hpp"

namespace tsah::cli {

namespace {

tsah::Vec3 jsonVec3(const nlohmann::json& j, const std::string& file, const char* key) {
  if (!j.contains(key) || !j[key].is_array() || j[key].size() != 3 || !j[key][0].is_number() ||
      !j[key][1].is_number() || !j[key][2].is_number())
    throw tsah::FileError(file, std::string("'") + key + "' must be an array of three numbers");
  const tsah::Vec3 v{j[key][0].get<float>(), j[key][1].get<float>(), j[key][2].get<float>()};
  if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))  // 1e39 becomes inf as a float
    throw tsah::FileError(file, std::string("'") + key + "' must hold three finite numbers (floats)");
  return v;
}

}  // namespace

// A camera file: {"eye": [x,y,z], "look_at": [x,y,z], "up": [x,y,z], "fov": degrees} for a fixed
// camera, or {"keys": [{"time": t, "eye": ..., "look_at": ..., "up": ..., "fov": ...}, ...]} for a path.
std::vector<anim::CameraKey> loadCameraFile(const std::string& path) {
  return decodeCameraFile(tsah::readFile(path, std::size_t(1) << 24), path);
}

std::vector<anim::CameraKey> decodeCameraFile(std::span<const uint8_t> bytes, const std::string& path) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(bytes.begin(), bytes.end());
  } catch (const nlohmann::json::exception& e) {
    throw tsah::FileError(path, std::string("not valid JSON: ") + e.what());
  }
  auto key = [&](const nlohmann::json& k) {
    if (!k.is_object()) throw tsah::FileError(path, "a camera must be a JSON object");
    anim::CameraKey c;
    const tsah::Vec3 eye = jsonVec3(k, path, "eye"), at = jsonVec3(k, path, "look_at");
    const tsah::Vec3 up = k.contains("up") ? jsonVec3(k, path, "up") : tsah::Vec3{0, 1, 0};
    c.eye = {eye.x, eye.y, eye.z};
    c.lookAt = {at.x, at.y, at.z};
    c.up = {up.x, up.y, up.z};
    if (k.contains("fov")) {
      if (!k["fov"].is_number()) throw tsah::FileError(path, "'fov' must be a number (degrees)");
      c.fovyDegrees = k["fov"].get<float>();
    }
    if (k.contains("time")) {
      if (!k["time"].is_number()) throw tsah::FileError(path, "'time' must be a number");
      c.time = k["time"].get<double>();
    }
    tsah::Camera check{eye, at, up, c.fovyDegrees};
    try {
      tsah::validateCamera(check);
    } catch (const tsah::Error& e) {
      throw tsah::FileError(path, e.what());
    }
    return c;
  };
  std::vector<anim::CameraKey> keys;
  if (j.is_object() && j.contains("keys")) {
    if (!j["keys"].is_array() || j["keys"].empty()) throw tsah::FileError(path, "'keys' must be a non-empty array");
    for (const auto& k : j["keys"]) keys.push_back(key(k));
    for (std::size_t i = 1; i < keys.size(); ++i)
      if (!(keys[i].time > keys[i - 1].time)) throw tsah::FileError(path, "camera key times must increase");
  } else {
    keys.push_back(key(j));
  }
  return keys;
}

}  // namespace tsah::cli
