#pragma once
// The render loop of tsah/render/renderer.hpp, written once for every traced scene: a CpuRuntime
// (one tree, renderFrame) and a two-level scene (tsah/scene/two_level_render.hpp). A Scene gives
// closestHit(ray) -> Hit (tri: the triangle's id in indices()), anyHit(ray, order) -> bool,
// parallelFor(n, grain, body), and the frame's mesh for shading: indices(), positions(),
// triangleCount(), vertexCount(). Scenes with blurred() also trace blurred frames (closestHit(ray,
// time), anyHit(ray, time, order)), and give the surface of a blurred hit through motionViewAt(time) (a
// CpuRuntime: blurredPrimarySurface) or blurredSurface(ray, hit, time, lighting) (a two-level view).
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/render/sampling.hpp"
#include "tsah/render/shading.hpp"

namespace tsah {

namespace detail {

// Area-weighted vertex normals of the current frame, 3 floats per vertex (shading only; rays use
// face normals).
inline std::vector<float> vertexNormals(const uint32_t* indices, const float* positions, uint32_t triangles,
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

inline double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

inline float length(Vec3 v) { return std::sqrt(dot(v, v)); }

// A secondary-ray pass over the image (surfaces: one per pixel, rows of `width`), in parallel over
// rows: castRays(pixel, surface, sample key), called for every pixel whose primary ray found a
// surface, returns how many rays it traced.
template <class Scene, class CastRays>
RayPassStats surfacePass(const Scene& runtime, uint32_t width, const std::vector<Surface>& surfaces,
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


// An any-hit query at the pixel's shutter time when the frame is blurred (runtimes that can blur),
// at the instant otherwise.
template <class Scene>
bool anyHitAt(const Scene& runtime, bool blurred, const Ray& ray, float time, AnyHitOrder order) {
  if constexpr (requires(const Scene& s) { s.blurred(); })
    if (blurred) return runtime.anyHit(ray, time, order);
  return runtime.anyHit(ray, order);
}

// The surface a blurred frame's primary hit at `time` finds: the hit triangle where it is then.
template <class Scene>
Surface blurredSurfaceOf(const Scene& runtime, const Ray& ray, const Hit& hit, float time, const SceneLighting& l) {
  if constexpr (requires(const Scene& s) { s.motionViewAt(0.0f); })
    return blurredPrimarySurface(ray, hit, runtime.motionViewAt(time), time, l);
  else
    return runtime.blurredSurface(ray, hit, time, l);
}
}  // namespace detail

template <class Scene>
RenderStats renderFrameOf(const Scene& runtime, const Camera& camera, const SceneLighting& lighting,
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
  constexpr bool canBlur = requires(const Scene& s) { s.blurred(); };
  bool blurred = false;
  if constexpr (canBlur) blurred = runtime.blurred();
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
        if constexpr (canBlur) {
          if (blurred) {
            const float time = pixelTime(i);
            surfaces[i] = detail::blurredSurfaceOf(runtime, ray, runtime.closestHit(ray, time), time, lighting);
            continue;
          }
        }
        surfaces[i] = primarySurface(ray, runtime.closestHit(ray), indices, positions, lighting);
      }
    rays += (y1 - y0) * width;
  });
  stats.primary = {rays.load(), detail::msSince(start)};

  // Pass 2: ambient occlusion, any hit within aoDistance.
  if (settings.aoSamples > 0)
    stats.ao = detail::surfacePass(runtime, width, surfaces, base, [&](std::size_t i, const Surface& s, SampleKey key) {
      uint32_t occluded = 0;
      for (uint32_t k = 0; k < settings.aoSamples; ++k)
        occluded += detail::anyHitAt(runtime, blurred, aoRay(s, key, k, lighting.aoDistance), pixelTime(i),
                             AnyHitOrder::TreeOrder)
                        ? 1u
                        : 0u;
      ao[i] = aoFactor(occluded, settings.aoSamples);
      return settings.aoSamples;
    });

  // Pass 3: shadow rays to points on the area light, any hit on the segment.
  if (settings.shadowSamples > 0)
    stats.shadow = detail::surfacePass(runtime, width, surfaces, base, [&](std::size_t i, const Surface& s, SampleKey key) {
      uint32_t visible = 0, cast = 0;
      for (uint32_t k = 0; k < settings.shadowSamples; ++k) {
        Ray ray;
        if (!shadowRay(s, lighting, key, k, ray)) continue;  // the light point is behind the surface
        ++cast;
        visible += detail::anyHitAt(runtime, blurred, ray, pixelTime(i), AnyHitOrder::FarthestFirst) ? 0u : 1u;
      }
      visibility[i] = lightVisibility(visible, settings.shadowSamples);
      return cast;
    });

  // Shading: diffuse sun with soft shadows + sky light scaled by ambient occlusion. (Blurred frames
  // take the smooth normals from the runtime's current positions; the geometric ones are exact.)
  start = std::chrono::steady_clock::now();
  const std::vector<float> normals = detail::vertexNormals(indices, positions, runtime.triangleCount(), runtime.vertexCount());
  runtime.parallelFor(height, 4, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        const Vec3 color = pixelColor(surfaces[i], cam.ray(float(x) + 0.5f, float(y) + 0.5f), ao[i], visibility[i],
                                      indices, normals.data(), lighting);
        storeSrgb8(image.pixel(x, uint32_t(y)), color);
      }
  });
  stats.shadeMs = detail::msSince(start);
  return stats;
}

}  // namespace tsah
