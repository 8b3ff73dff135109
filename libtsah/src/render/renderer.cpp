#include "tsah/render/renderer.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/render/shading.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah {

namespace {

// Area-weighted vertex normals of the current frame, 3 floats per vertex (shading only; rays use
// face normals).
std::vector<float> vertexNormals(const uint32_t* indices, const float* positions, uint32_t triangles,
                                 uint32_t vertices) {
  std::vector<float> n(std::size_t(vertices) * 3, 0.0f);
  for (uint32_t t = 0; t < triangles; ++t) {
    const Vec3 face = faceNormal(indices, positions, t);
    for (int k = 0; k < 3; ++k) {
      float* v = n.data() + 3 * std::size_t(indices[3 * std::size_t(t) + k]);
      v[0] += face.x;
      v[1] += face.y;
      v[2] += face.z;
    }
  }
  return n;
}

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

float length(Vec3 v) { return std::sqrt(dot(v, v)); }

// A secondary-ray pass over the image (surfaces: one per pixel, rows of `width`), in parallel over
// rows: castRays(pixel, surface, sample key), called for every pixel whose primary ray found a
// surface, returns how many rays it traced.
template <class CastRays>
RayPassStats surfacePass(const CpuRuntime& runtime, uint32_t width, const std::vector<Surface>& surfaces,
                         SampleKey base, const CastRays& castRays) {
  std::atomic<uint64_t> rays{0};
  const auto start = std::chrono::steady_clock::now();
  runtime.parallelFor(surfaces.size() / width, 1, [&](std::size_t y0, std::size_t y1) {
    uint64_t local = 0;
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        if (surfaces[i].kind == SurfaceKind::None) continue;
        SampleKey key = base;
        key.pixel = uint32_t(i);
        local += castRays(i, surfaces[i], key);
      }
    rays += local;
  });
  return {rays.load(), msSince(start)};
}

}  // namespace

// The surface a primary ray at shutter fraction `time` finds in a blurred frame: the hit triangle's
// vertices lerped at that time (as the traversal lerps them), as a one-triangle mesh.
Surface blurredSurface(const CpuRuntime& runtime, const Ray& ray, float time, const SceneLighting& lighting) {
  const Hit hit = runtime.closestHit(ray, time);
  if (!hit.valid()) return primarySurface(ray, hit, nullptr, nullptr, lighting);
  const MotionBvhView& view = runtime.motionView();
  const motion::Segment seg = motion::segmentAt(view.keyTimes, int(view.keyCount), time);
  const float* p0 = view.keyPositions + std::size_t(seg.index) * view.vertexCount * 3;
  const float* p1 = p0 + std::size_t(view.vertexCount) * 3;
  float triangle[9];
  for (int k = 0; k < 3; ++k) {
    const uint32_t vertex = runtime.indices()[3 * std::size_t(hit.tri) + k];
    const Vec3 v = motion::lerpVertex(loadVec3(p0, vertex), loadVec3(p1, vertex), seg.f);
    triangle[3 * k] = v.x;
    triangle[3 * k + 1] = v.y;
    triangle[3 * k + 2] = v.z;
  }
  static constexpr uint32_t kOneTriangle[3] = {0, 1, 2};
  Hit local = hit;
  local.tri = 0;
  Surface s = primarySurface(ray, local, kOneTriangle, triangle, lighting);
  if (s.kind == SurfaceKind::Mesh) s.tri = hit.tri;
  return s;
}

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
  if (settings.width == 0 || settings.height == 0) throw tsah::ConfigError("render: the image size must be positive");
  validateCamera(camera);
  tsah::checkFitsInMemory(renderFrameBytes(settings, runtime.vertexCount()), "render",
                          "a " + std::to_string(settings.width) + "x" + std::to_string(settings.height) + " frame");
  const uint32_t width = settings.width, height = settings.height;
  const std::size_t pixels = std::size_t(width) * height;
  if (image.width != width || image.height != height) image = Image(width, height);

  const uint32_t* indices = runtime.indices().data();
  const float* positions = runtime.positions().data();
  const CameraRays cam = cameraRays(camera, width, height);
  std::vector<Surface> surfaces(pixels);
  std::vector<float> ao(pixels, 1.0f), visibility(pixels, 1.0f);
  RenderStats stats;
  const SampleKey base{settings.seed, settings.frame, 0};
  // A blurred frame: every ray of a pixel at the pixel's shutter time; otherwise the instant.
  const bool blurred = runtime.blurred();
  auto pixelTime = [&](std::size_t pixel) {
    SampleKey key = base;
    key.pixel = uint32_t(pixel);
    return pixelShutterTime(key);
  };

  // Pass 1: primary rays, closest hit; the ground plane is intersected analytically.
  std::atomic<uint64_t> rays{0};
  auto start = std::chrono::steady_clock::now();
  runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const Ray ray = cam.ray(float(x) + 0.5f, float(y) + 0.5f);
        const std::size_t i = y * width + x;
        surfaces[i] = blurred ? blurredSurface(runtime, ray, pixelTime(i), lighting)
                              : primarySurface(ray, runtime.closestHit(ray), indices, positions, lighting);
      }
    rays += (y1 - y0) * width;
  });
  stats.primary = {rays.load(), msSince(start)};

  // Pass 2: ambient occlusion, any hit within aoDistance.
  if (settings.aoSamples > 0)
    stats.ao = surfacePass(runtime, width, surfaces, base, [&](std::size_t i, const Surface& s, SampleKey key) {
      uint32_t occluded = 0;
      for (uint32_t k = 0; k < settings.aoSamples; ++k)
        occluded += (blurred ? runtime.anyHit(aoRay(s, key, k, lighting.aoDistance), pixelTime(i),
                                              AnyHitOrder::TreeOrder)
                             : runtime.anyHit(aoRay(s, key, k, lighting.aoDistance), AnyHitOrder::TreeOrder))
                        ? 1u
                        : 0u;
      ao[i] = aoFactor(occluded, settings.aoSamples);
      return settings.aoSamples;
    });

  // Pass 3: shadow rays to points on the area light, any hit on the segment.
  if (settings.shadowSamples > 0)
    stats.shadow = surfacePass(runtime, width, surfaces, base, [&](std::size_t i, const Surface& s, SampleKey key) {
      uint32_t visible = 0, cast = 0;
      for (uint32_t k = 0; k < settings.shadowSamples; ++k) {
        Ray ray;
        if (!shadowRay(s, lighting, key, k, ray)) continue;  // the light point is behind the surface
        ++cast;
        visible += (blurred ? runtime.anyHit(ray, pixelTime(i)) : runtime.anyHit(ray)) ? 0u : 1u;
      }
      visibility[i] = lightVisibility(visible, settings.shadowSamples);
      return cast;
    });

  // Shading: diffuse sun with soft shadows + sky light scaled by ambient occlusion. (Blurred frames
  // take the smooth normals from the runtime's current positions; the geometric ones are exact.)
  start = std::chrono::steady_clock::now();
  const std::vector<float> normals = vertexNormals(indices, positions, runtime.triangleCount(), runtime.vertexCount());
  runtime.parallelFor(height, 4, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        const Vec3 color = pixelColor(surfaces[i], cam.ray(float(x) + 0.5f, float(y) + 0.5f), ao[i], visibility[i],
                                      indices, normals.data(), lighting);
        storeSrgb8(image.pixel(x, uint32_t(y)), color);
      }
  });
  stats.shadeMs = msSince(start);
  return stats;
}

}  // namespace tsah
