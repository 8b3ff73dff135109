#include "tsah/render/camera_path.hpp"

#include <algorithm>
#include <array>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

Vec3 toVec3(const std::array<float, 3>& a) { return {a[0], a[1], a[2]}; }

Vec3 lerp(Vec3 a, Vec3 b, float s) { return a + (b - a) * s; }

}  // namespace

Camera cameraAt(std::span<const anim::CameraKey> path, double t) {
  if (path.empty()) throw tsah::ConfigError("camera path is empty");
  auto toCamera = [](const anim::CameraKey& k) {
    Camera c;
    c.eye = toVec3(k.eye);
    c.lookAt = toVec3(k.lookAt);
    c.up = toVec3(k.up);
    c.fovYDegrees = k.fovyDegrees;
    return c;
  };
  if (t <= path.front().time || path.size() == 1) return toCamera(path.front());
  if (t >= path.back().time) return toCamera(path.back());
  const auto next = std::upper_bound(path.begin(), path.end(), t,
                                     [](double time, const anim::CameraKey& k) { return time < k.time; });
  const anim::CameraKey& b = *next;
  const anim::CameraKey& a = *(next - 1);
  const double span = b.time - a.time;
  const float s = span > 0.0 ? float((t - a.time) / span) : 0.0f;
  Camera c;
  c.eye = lerp(toVec3(a.eye), toVec3(b.eye), s);
  c.lookAt = lerp(toVec3(a.lookAt), toVec3(b.lookAt), s);
  c.up = normalize(lerp(toVec3(a.up), toVec3(b.up), s));
  c.fovYDegrees = a.fovyDegrees + (b.fovyDegrees - a.fovyDegrees) * s;
  return c;
}

}  // namespace tsah
