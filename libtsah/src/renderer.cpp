#include "tsah/renderer.hpp"

#include <atomic>
#include <chrono>
#include <cmath>

#include "anim/error.hpp"
#include "tsah/sampling.hpp"
#include "tsah/traversal.hpp"

namespace tsah {

namespace {

enum class SurfaceKind : uint32_t { None = 0, Mesh = 1, Ground = 2 };

// What the primary pass found at a pixel; the secondary passes start from it.
struct Surface {
  Vec3 position;  // already offset along the normal
  Vec3 normal;    // geometric, unit, facing the camera: secondary rays leave on this side
  SurfaceKind kind = SurfaceKind::None;
  uint32_t tri = 0;  // mesh hits: triangle and barycentrics, for the smooth shading normal
  float u = 0.0f, v = 0.0f;
};

// Area-weighted vertex normals of the current frame (for shading only; rays use face normals).
std::vector<Vec3> vertexNormals(const BvhView& bvh, uint32_t triangles, uint32_t vertices) {
  std::vector<Vec3> n(vertices, Vec3{0, 0, 0});
  for (uint32_t t = 0; t < triangles; ++t) {
    const uint32_t* tri = bvh.indices + 3 * std::size_t(t);
    const Vec3 v0 = bvh.vertex(tri[0]);
    const Vec3 face = cross(bvh.vertex(tri[1]) - v0, bvh.vertex(tri[2]) - v0);
    for (int k = 0; k < 3; ++k) n[tri[k]] = n[tri[k]] + face;
  }
  return n;
}

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

float length(Vec3 v) { return std::sqrt(dot(v, v)); }

Vec3 mul(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
Vec3 mix(Vec3 a, Vec3 b, float s) { return a + (b - a) * s; }

// Dimensions of the per-sample random numbers, so passes draw independent numbers.
constexpr uint32_t kDimAo = 0, kDimShadow = 2;

Vec3 skyColor(Vec3 dir, Vec3 up) {
  const float h = dot(dir, up);
  const Vec3 horizon{0.80f, 0.85f, 0.91f}, zenith{0.30f, 0.48f, 0.78f}, below{0.40f, 0.39f, 0.37f};
  if (h < 0.0f) return mix(horizon, below, std::min(1.0f, -h * 4.0f));
  return mix(horizon, zenith, std::sqrt(h));
}

uint8_t toSrgb8(float linear) {
  const float c = std::clamp(linear, 0.0f, 1.0f);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
  return static_cast<uint8_t>(std::lround(s * 255.0f));
}

}  // namespace

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

RenderStats renderFrame(const CpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                        const RenderSettings& settings, Image& image) {
  if (settings.width == 0 || settings.height == 0) throw anim::Error("render: the image size must be positive");
  validateCamera(camera);
  const uint32_t width = settings.width, height = settings.height;
  const std::size_t pixels = std::size_t(width) * height;
  if (image.width != width || image.height != height) image = Image(width, height);

  const BvhView bvh = runtime.view();
  const CameraRays cam = cameraRays(camera, width, height);
  const Vec3 up = lighting.up;
  std::vector<Surface> surfaces(pixels);
  std::vector<float> ao(pixels, 1.0f), visibility(pixels, 1.0f);
  RenderStats stats;
  const SampleKey base{settings.seed, settings.frame, 0};

  // Pass 1: primary rays, closest hit; the ground plane is intersected analytically.
  std::atomic<uint64_t> rays{0};
  auto start = std::chrono::steady_clock::now();
  runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const Ray ray = cam.ray(float(x) + 0.5f, float(y) + 0.5f);
        const Hit hit = closestHit(bvh, ray);
        float tGround = 3.402823466e38f;
        if (lighting.ground) {
          const float denom = dot(ray.dir, up);
          if (denom < 0.0f) {
            const float t = (lighting.groundHeight - dot(ray.org, up)) / denom;
            if (t > 0.0f) tGround = t;
          }
        }
        Surface& s = surfaces[y * width + x];
        if (hit.valid() && hit.t <= tGround) {
          const uint32_t* tri = bvh.indices + 3 * std::size_t(hit.tri);
          const Vec3 v0 = bvh.vertex(tri[0]), v1 = bvh.vertex(tri[1]), v2 = bvh.vertex(tri[2]);
          Vec3 n = normalize(cross(v1 - v0, v2 - v0));
          if (dot(n, ray.dir) > 0.0f) n = n * -1.0f;
          const Vec3 p = v0 * (1.0f - hit.u - hit.v) + v1 * hit.u + v2 * hit.v;
          s = {p + n * lighting.epsilon, n, SurfaceKind::Mesh, hit.tri, hit.u, hit.v};
        } else if (tGround < 3.402823466e38f) {
          s = {ray.org + ray.dir * tGround + up * lighting.epsilon, up, SurfaceKind::Ground};
        }
      }
    rays += (y1 - y0) * width;
  });
  stats.primary = {rays.load(), msSince(start)};

  // Pass 2: ambient occlusion, any hit within aoDistance.
  rays = 0;
  start = std::chrono::steady_clock::now();
  if (settings.aoSamples > 0)
    runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
      uint64_t local = 0;
      for (std::size_t y = y0; y < y1; ++y)
        for (uint32_t x = 0; x < width; ++x) {
          const std::size_t i = y * width + x;
          const Surface& s = surfaces[i];
          if (s.kind == SurfaceKind::None) continue;
          SampleKey key = base;
          key.pixel = uint32_t(i);
          uint32_t occluded = 0;
          for (uint32_t k = 0; k < settings.aoSamples; ++k) {
            Ray ray;
            ray.org = s.position;
            ray.dir = cosineHemisphere(s.normal, sampleUniform(key, k, kDimAo), sampleUniform(key, k, kDimAo + 1));
            ray.tmin = 0.0f;
            ray.tmax = lighting.aoDistance;
            occluded += anyHit(bvh, ray) ? 1u : 0u;
          }
          local += settings.aoSamples;
          ao[i] = 1.0f - float(occluded) / float(settings.aoSamples);
        }
      rays += local;
    });
  stats.ao = {rays.load(), msSince(start)};

  // Pass 3: shadow rays to points on the area light, any hit on the segment.
  rays = 0;
  start = std::chrono::steady_clock::now();
  if (settings.shadowSamples > 0)
    runtime.parallelFor(height, 1, [&](std::size_t y0, std::size_t y1) {
      uint64_t local = 0;
      for (std::size_t y = y0; y < y1; ++y)
        for (uint32_t x = 0; x < width; ++x) {
          const std::size_t i = y * width + x;
          const Surface& s = surfaces[i];
          if (s.kind == SurfaceKind::None) continue;
          SampleKey key = base;
          key.pixel = uint32_t(i);
          const Vec3 axis = normalize(lighting.lightCenter - s.position);
          uint32_t visible = 0;
          for (uint32_t k = 0; k < settings.shadowSamples; ++k) {
            const Vec3 q = sampleDisk(lighting.lightCenter, axis, lighting.lightRadius,
                                      sampleUniform(key, k, kDimShadow), sampleUniform(key, k, kDimShadow + 1));
            Ray ray;
            ray.org = s.position;
            ray.dir = q - s.position;
            ray.tmin = 0.0f;
            ray.tmax = 1.0f;
            if (dot(ray.dir, s.normal) <= 0.0f) continue;  // the light point is behind the surface
            ++local;
            visible += anyHit(bvh, ray) ? 0u : 1u;
          }
          visibility[i] = float(visible) / float(settings.shadowSamples);
        }
      rays += local;
    });
  stats.shadow = {rays.load(), msSince(start)};

  // Shading: diffuse sun with soft shadows + sky light scaled by ambient occlusion.
  start = std::chrono::steady_clock::now();
  const std::vector<Vec3> normals = vertexNormals(bvh, runtime.triangleCount(), runtime.vertexCount());
  const Vec3 meshAlbedo{0.78f, 0.60f, 0.44f};
  const Vec3 sun{1.00f, 0.94f, 0.84f};
  runtime.parallelFor(height, 4, [&](std::size_t y0, std::size_t y1) {
    for (std::size_t y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const std::size_t i = y * width + x;
        const Surface& s = surfaces[i];
        Vec3 color;
        if (s.kind == SurfaceKind::None) {
          color = skyColor(cam.ray(float(x) + 0.5f, float(y) + 0.5f).dir, up);
        } else {
          Vec3 albedo = meshAlbedo;
          Vec3 shading = s.normal;
          float fade = 0.0f;
          if (s.kind == SurfaceKind::Mesh) {
            const uint32_t* tri = bvh.indices + 3 * std::size_t(s.tri);
            const Vec3 smooth = normalize(normals[tri[0]] * (1.0f - s.u - s.v) + normals[tri[1]] * s.u +
                                          normals[tri[2]] * s.v);
            shading = dot(smooth, s.normal) < 0.0f ? smooth * -1.0f : smooth;
          }
          if (s.kind == SurfaceKind::Ground) {
            Vec3 t, b;
            orthonormalBasis(up, t, b);
            const Vec3 rel = s.position - lighting.sceneCenter;
            const auto cu = int32_t(std::floor(dot(rel, t) / lighting.groundScale));
            const auto cv = int32_t(std::floor(dot(rel, b) / lighting.groundScale));
            albedo = ((cu + cv) & 1) ? Vec3{0.62f, 0.60f, 0.56f} : Vec3{0.50f, 0.49f, 0.46f};
            const float d = length(rel) / (6.0f * lighting.sceneRadius);
            fade = 1.0f - std::exp(-d * d);
          }
          const Vec3 toLight = normalize(lighting.lightCenter - s.position);
          const float diffuse = std::max(0.0f, dot(shading, toLight)) * visibility[i];
          const Vec3 sky = skyColor(normalize(shading + up * 0.5f), up) * 0.6f;
          const Vec3 lit = sky * ao[i] + sun * diffuse;
          color = mul(albedo, lit);
          if (fade > 0.0f) color = mix(color, Vec3{0.80f, 0.85f, 0.91f}, fade);  // into the horizon
        }
        uint8_t* px = image.pixel(x, uint32_t(y));
        px[0] = toSrgb8(color.x);
        px[1] = toSrgb8(color.y);
        px[2] = toSrgb8(color.z);
      }
  });
  stats.shadeMs = msSince(start);
  return stats;
}

}  // namespace tsah
