#include "tsah/render/renderer.hpp"
#include "tsah/render/render_loop.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/render/shading.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah {

using detail::length;

SceneLighting fitLighting(const Aabb& bounds, const Camera& camera, Vec3 up, float aoFraction, bool ground) {
  SceneLighting l;
  l.up = normalize(up);
  l.ground = ground;
  if (bounds.empty()) return l;
  const Vec3 center = bounds.center();
  const float diagonal = std::max(length(bounds.extent()), 1e-6f);
  const float radius = 0.5f * diagonal;
  l.sceneCenter = center;
  l.sceneRadius = radius;
  l.aoDistance = aoFraction * diagonal;
  l.epsilon = 1e-4f * diagonal;
  // Light: high above, turned 60 degrees from the camera around the up axis, so the shadows fall
  // to the side where the camera sees them.
  Vec3 toEye = camera.eye - center;
  toEye = toEye - l.up * dot(toEye, l.up);
  if (!(length(toEye) > 1e-6f * radius)) {
    Vec3 b;
    orthonormalBasis(l.up, toEye, b);
  }
  toEye = normalize(toEye);
  const Vec3 side = normalize(cross(l.up, toEye));
  const float angle = 60.0f * 3.14159265f / 180.0f;
  const Vec3 horizontal = toEye * std::cos(angle) + side * std::sin(angle);
  l.lightCenter = center + l.up * (2.5f * radius) + horizontal * (1.5f * radius);
  l.lightRadius = 0.3f * radius;
  // The ground just below the lowest point of the box along up.
  float lowest = 3.4e38f;
  for (int c = 0; c < 8; ++c) {
    const Vec3 p{(c & 1) ? bounds.hi.x : bounds.lo.x, (c & 2) ? bounds.hi.y : bounds.lo.y,
                 (c & 4) ? bounds.hi.z : bounds.lo.z};
    lowest = std::min(lowest, dot(p, l.up));
  }
  l.groundHeight = lowest - 1e-3f * radius;
  l.groundScale = radius / 3.0f;
  return l;
}

std::size_t renderFrameBytes(const RenderSettings& settings, uint32_t vertices) {
  const std::size_t pixels = std::size_t(settings.width) * settings.height;
  return pixels * (sizeof(Surface) + 2 * sizeof(float) + 3) + std::size_t(vertices) * 3 * sizeof(float);
}

RenderStats renderFrame(const CpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                        const RenderSettings& settings, Image& image) {
  return renderFrameOf(runtime, camera, lighting, settings, image);
}

}  // namespace tsah
