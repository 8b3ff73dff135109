#pragma once
// The per-pixel math of the renderers, one definition for the CPU renderer (renderer.cpp) and the
// GPU renderer (cuda_kernels/src/render.cu): the scene's lighting, the surface a primary ray finds
// (mesh or analytic ground), the ambient-occlusion and shadow rays leaving it, and the shading that
// turns their results into a colour. The renderers only decide how pixels are scheduled and where
// the intermediate results live.
//
// CPU and GPU agree bit for bit on everything but cosf/sinf/powf/expf (the CUDA and C libraries may
// round those differently in the last bit) provided that the device code is compiled without fused
// multiply-adds (-fmad=false; the x86-64 CPU build has none) and with IEEE division and square
// root (nvcc's default; not --use_fast_math).
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/traversal.hpp"  // MotionBvhView
#include "tsah/render/sampling.hpp"

namespace tsah {

struct SceneLighting {
  Vec3 lightCenter{0, 10, 0};
  float lightRadius = 1.0f;    // spherical area light, sampled as a disk facing the shaded point
  float aoDistance = 1.0f;     // maximum length of ambient-occlusion rays
  float epsilon = 1e-4f;       // offset of secondary ray origins along the normal (scene units)
  bool ground = true;          // a plane below the scene
  Vec3 up{0, 1, 0};            // scene up: the ground's normal and the sky's zenith
  float groundHeight = 0.0f;   // the plane is dot(p, up) == groundHeight
  float groundScale = 1.0f;    // size of the ground's checker squares
  Vec3 sceneCenter{0, 0, 0};   // for the ground's fade into the horizon
  float sceneRadius = 1.0f;
};

// Dimensions of the per-sample random numbers, so that the passes draw independent numbers.
inline constexpr uint32_t kSampleDimAo = 0, kSampleDimShadow = 2;
inline constexpr float kNoDistance = 3.402823466e38f;

enum class SurfaceKind : uint32_t { None = 0, Mesh = 1, Ground = 2 };

// What the primary ray found at a pixel; the secondary rays start from it.
struct Surface {
  Vec3 position{0, 0, 0};  // already offset along the normal
  Vec3 normal{0, 0, 1};    // geometric, unit, facing the camera: secondary rays leave on this side
  SurfaceKind kind = SurfaceKind::None;
  uint32_t tri = 0;  // mesh hits: triangle and barycentrics, for the smooth shading normal
  float u = 0.0f, v = 0.0f;
};

TSAH_HD Vec3 loadVec3(const float* xyz, uint32_t i) {
  return {xyz[3 * std::size_t(i)], xyz[3 * std::size_t(i) + 1], xyz[3 * std::size_t(i) + 2]};
}

// Area-weighted (unnormalized) normal of triangle t; a vertex normal is the sum of its triangles'
// face normals in increasing triangle order (both renderers sum in that order).
TSAH_HD Vec3 faceNormal(const uint32_t* indices, const float* positions, uint32_t t) {
  const uint32_t* tri = indices + 3 * std::size_t(t);
  const Vec3 v0 = loadVec3(positions, tri[0]);
  return cross(loadVec3(positions, tri[1]) - v0, loadVec3(positions, tri[2]) - v0);
}

// The surface a primary ray finds: the mesh hit (indices/positions: the frame's triangles) unless
// the analytic ground plane is nearer, the ground, or nothing.
TSAH_HD Surface primarySurface(const Ray& ray, const Hit& hit, const uint32_t* indices, const float* positions,
                               const SceneLighting& l) {
  float tGround = kNoDistance;
  if (l.ground) {
    const float denom = dot(ray.dir, l.up);
    if (denom < 0.0f) {
      const float t = (l.groundHeight - dot(ray.org, l.up)) / denom;
      if (t > 0.0f) tGround = t;
    }
  }
  Surface s;
  if (hit.valid() && hit.t <= tGround) {
    const uint32_t* tri = indices + 3 * std::size_t(hit.tri);
    const Vec3 v0 = loadVec3(positions, tri[0]), v1 = loadVec3(positions, tri[1]), v2 = loadVec3(positions, tri[2]);
    Vec3 n = normalize(cross(v1 - v0, v2 - v0));
    if (dot(n, ray.dir) > 0.0f) n = n * -1.0f;
    const Vec3 p = v0 * (1.0f - hit.u - hit.v) + v1 * hit.u + v2 * hit.v;
    s = {p + n * l.epsilon, n, SurfaceKind::Mesh, hit.tri, hit.u, hit.v};
  } else if (tGround < kNoDistance) {
    s.position = ray.org + ray.dir * tGround + l.up * l.epsilon;
    s.normal = l.up;
    s.kind = SurfaceKind::Ground;
  }
  return s;
}

// primarySurface on one triangle given by its three vertices (9 floats: where a blurred frame has
// it at the ray's time); s.tri is hit.tri.
TSAH_HD Surface primarySurfaceOnTriangle(const Ray& ray, const Hit& hit, const float* triangle, const SceneLighting& l) {
  const uint32_t oneTriangle[3] = {0, 1, 2};
  Hit local = hit;
  local.tri = 0;
  Surface s = primarySurface(ray, local, oneTriangle, triangle, l);
  if (s.kind == SurfaceKind::Mesh) s.tri = hit.tri;
  return s;
}

// The surface a primary ray at shutter fraction `time` finds in a blurred frame (hit: the closest
// hit at that time): the hit triangle's vertices lerped at that time, as the traversal lerps them,
// then primarySurface on that one triangle; s.tri is the hit's triangle id.
TSAH_HD Surface blurredPrimarySurface(const Ray& ray, const Hit& hit, const MotionBvhView& view, float time,
                                      const SceneLighting& l) {
  if (!hit.valid()) return primarySurface(ray, hit, nullptr, nullptr, l);
  const motion::Segment seg = motion::segmentAt(view.keyTimes, int(view.keyCount), time);
  const float* p0 = view.keyPositions + std::size_t(seg.index) * view.vertexCount * 3;
  const float* p1 = view.keyCount > 1 ? p0 + std::size_t(view.vertexCount) * 3 : p0;
  float triangle[9];
  for (int k = 0; k < 3; ++k) {
    const uint32_t vertex = view.indices[3 * std::size_t(hit.tri) + k];
    const Vec3 v = motion::lerpVertex(loadVec3(p0, vertex), loadVec3(p1, vertex), seg.f);
    triangle[3 * k] = v.x;
    triangle[3 * k + 1] = v.y;
    triangle[3 * k + 2] = v.z;
  }
  return primarySurfaceOnTriangle(ray, hit, triangle, l);
}

// Ambient-occlusion ray k of a surface (kind != None): cosine hemisphere, any hit within aoDistance.
TSAH_HD Ray aoRay(const Surface& s, const SampleKey& key, uint32_t k, float aoDistance) {
  Ray ray;
  ray.org = s.position;
  ray.dir = cosineHemisphere(s.normal, sampleUniform(key, k, kSampleDimAo), sampleUniform(key, k, kSampleDimAo + 1));
  ray.tmin = 0.0f;
  ray.tmax = aoDistance;
  return ray;
}

// Shadow ray k of a surface (kind != None) to a point of the light's disk, as a segment (t in
// [0, 1]). False when that point lies behind the surface: no ray is cast and the sample is unlit.
TSAH_HD bool shadowRay(const Surface& s, const SceneLighting& l, const SampleKey& key, uint32_t k, Ray& ray) {
  const Vec3 axis = normalize(l.lightCenter - s.position);
  const Vec3 q = sampleDisk(l.lightCenter, axis, l.lightRadius, sampleUniform(key, k, kSampleDimShadow),
                            sampleUniform(key, k, kSampleDimShadow + 1));
  ray.org = s.position;
  ray.dir = q - s.position;
  ray.tmin = 0.0f;
  ray.tmax = 1.0f;
  return dot(ray.dir, s.normal) > 0.0f;
}

// Fraction of the sky a surface sees (1 without AO rays) and of the light it sees (1 without
// shadow rays).
TSAH_HD float aoFactor(uint32_t occluded, uint32_t samples) {
  return samples > 0 ? 1.0f - float(occluded) / float(samples) : 1.0f;
}
TSAH_HD float lightVisibility(uint32_t visible, uint32_t samples) {
  return samples > 0 ? float(visible) / float(samples) : 1.0f;
}

TSAH_HD Vec3 mix(Vec3 a, Vec3 b, float s) { return a + (b - a) * s; }
TSAH_HD Vec3 mul(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }

TSAH_HD Vec3 horizonColor() { return {0.80f, 0.85f, 0.91f}; }

// The sky seen in direction dir (unit): horizon to zenith above, a dim ground colour below.
TSAH_HD Vec3 skyColor(Vec3 dir, Vec3 up) {
  const float h = dot(dir, up);
  const Vec3 zenith{0.30f, 0.48f, 0.78f}, below{0.40f, 0.39f, 0.37f};
  if (h < 0.0f) return mix(horizonColor(), below, fminf_(1.0f, -h * 4.0f));
  return mix(horizonColor(), zenith, sqrtf(h));
}

// Linear colour of a surface (kind != None): diffuse sun with soft shadows plus sky light scaled by
// ambient occlusion; mesh surfaces use the smooth normal interpolated from vertexNormals (3 floats
// per vertex, unnormalized sums of faceNormal), the ground is a checkerboard fading into the horizon.
TSAH_HD Vec3 shadeSurface(const Surface& s, float ao, float visibility, const uint32_t* indices,
                          const float* vertexNormals, const SceneLighting& l) {
  const Vec3 meshAlbedo{0.78f, 0.60f, 0.44f};
  const Vec3 sun{1.00f, 0.94f, 0.84f};
  Vec3 albedo = meshAlbedo;
  Vec3 shading = s.normal;
  float fade = 0.0f;
  if (s.kind == SurfaceKind::Mesh) {
    const uint32_t* tri = indices + 3 * std::size_t(s.tri);
    const Vec3 smooth = normalize(loadVec3(vertexNormals, tri[0]) * (1.0f - s.u - s.v) +
                                  loadVec3(vertexNormals, tri[1]) * s.u + loadVec3(vertexNormals, tri[2]) * s.v);
    shading = dot(smooth, s.normal) < 0.0f ? smooth * -1.0f : smooth;
  } else if (s.kind == SurfaceKind::Ground) {
    Vec3 t, b;
    orthonormalBasis(l.up, t, b);
    const Vec3 rel = s.position - l.sceneCenter;
    const auto cu = int32_t(floorf(dot(rel, t) / l.groundScale));
    const auto cv = int32_t(floorf(dot(rel, b) / l.groundScale));
    albedo = ((cu + cv) & 1) ? Vec3{0.62f, 0.60f, 0.56f} : Vec3{0.50f, 0.49f, 0.46f};
    const float d = sqrtf(dot(rel, rel)) / (6.0f * l.sceneRadius);
    fade = 1.0f - expf(-d * d);
  }
  const Vec3 toLight = normalize(l.lightCenter - s.position);
  const float diffuse = fmaxf_(dot(shading, toLight), 0.0f) * visibility;
  const Vec3 sky = skyColor(normalize(shading + l.up * 0.5f), l.up) * 0.6f;
  const Vec3 lit = sky * ao + sun * diffuse;
  Vec3 color = mul(albedo, lit);
  if (fade > 0.0f) color = mix(color, horizonColor(), fade);  // into the horizon
  return color;
}

// Colour of a pixel whose primary ray is cameraRay: the sky where it found nothing.
TSAH_HD Vec3 pixelColor(const Surface& s, const Ray& cameraRay, float ao, float visibility, const uint32_t* indices,
                        const float* vertexNormals, const SceneLighting& l) {
  if (s.kind == SurfaceKind::None) return skyColor(cameraRay.dir, l.up);
  return shadeSurface(s, ao, visibility, indices, vertexNormals, l);
}

// Linear [0, 1] to an 8-bit sRGB value (NaN and negatives give 0).
TSAH_HD uint8_t toSrgb8(float linear) {
  const float c = !(linear > 0.0f) ? 0.0f : (linear < 1.0f ? linear : 1.0f);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * powf(c, 1.0f / 2.4f) - 0.055f;
  return static_cast<uint8_t>(lroundf(s * 255.0f));
}

TSAH_HD void storeSrgb8(uint8_t* rgb, Vec3 linear) {
  rgb[0] = toSrgb8(linear.x);
  rgb[1] = toSrgb8(linear.y);
  rgb[2] = toSrgb8(linear.z);
}

}  // namespace tsah
