#include "tsah/render/camera.hpp"

#include <algorithm>
#include <cmath>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

float length(Vec3 v) { return std::sqrt(dot(v, v)); }


}  // namespace

void validateCamera(const Camera& c) {
  const Vec3 view = c.lookAt - c.eye;
  if (!(length(view) > 0.0f)) throw tsah::ConfigError("camera: eye and look-at point coincide");
  if (!(length(cross(normalize(view), normalize(c.up))) > 1e-4f) || !(length(c.up) > 0.0f))
    throw tsah::ConfigError("camera: the up vector is zero or parallel to the view direction");
  if (!(c.fovYDegrees > 0.0f && c.fovYDegrees < 180.0f))
    throw tsah::ConfigError("camera: the field of view must be between 0 and 180 degrees");
  for (const Vec3& v : {c.eye, c.lookAt, c.up})
    if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
      throw tsah::ConfigError("camera: a coordinate is not finite");
}

Camera fitCamera(const Aabb& bounds, Vec3 up, float fovYDegrees, float aspect) {
  Camera cam;
  cam.up = normalize(up);
  cam.fovYDegrees = fovYDegrees;
  if (bounds.empty()) return cam;
  const Vec3 center = bounds.center();
  const Vec3 ext = bounds.extent();
  const float radius = std::max(0.5f * length(ext), 1e-6f);

  // The horizontal axis (perpendicular to up) along which the box is thinnest: look along it so
  // the larger side faces the camera; then turn 35 degrees and lift 20 degrees for depth.
  Vec3 side, front;
  orthonormalBasis(cam.up, side, front);
  auto extentAlong = [&](Vec3 axis) {
    return std::abs(axis.x) * ext.x + std::abs(axis.y) * ext.y + std::abs(axis.z) * ext.z;
  };
  // Pick among the world axes most perpendicular to up for a natural orientation.
  Vec3 best = side;
  float bestScore = 3.4e38f;
  for (Vec3 axis : {Vec3{1, 0, 0}, Vec3{0, 0, 1}, Vec3{0, 1, 0}, Vec3{-1, 0, 0}, Vec3{0, 0, -1}}) {
    const Vec3 h = normalize(axis - cam.up * dot(axis, cam.up));
    if (std::abs(dot(axis, cam.up)) > 0.9f) continue;
    const float score = extentAlong(h);
    if (score < bestScore - 1e-6f * radius) {
      bestScore = score;
      best = h;
    }
  }
  const Vec3 across = normalize(cross(cam.up, best));
  const float yaw = 35.0f * 3.14159265f / 180.0f, pitch = 20.0f * 3.14159265f / 180.0f;
  const Vec3 horizontal = best * std::cos(yaw) + across * std::sin(yaw);
  const Vec3 dir = normalize(horizontal * std::cos(pitch) + cam.up * std::sin(pitch));

  const float halfY = 0.5f * fovYDegrees * 3.14159265f / 180.0f;
  const float halfX = std::atan(std::tan(halfY) * aspect);
  const float distance = 1.08f * radius / std::sin(std::min(halfX, halfY));
  cam.lookAt = center;
  cam.eye = center + dir * distance;
  return cam;
}

CameraRays cameraRays(const Camera& camera, uint32_t width, uint32_t height) {
  const Vec3 w = normalize(camera.lookAt - camera.eye);
  const Vec3 u = normalize(cross(w, camera.up));  // right
  const Vec3 v = cross(u, w);                     // up on screen
  const float halfH = std::tan(0.5f * camera.fovYDegrees * 3.14159265f / 180.0f);
  const float halfW = halfH * float(width) / float(height);
  CameraRays r;
  r.eye = camera.eye;
  r.dx = u * (2.0f * halfW / float(width));
  r.dy = v * (-2.0f * halfH / float(height));
  r.corner = w - u * halfW + v * halfH;
  return r;
}

}  // namespace tsah
