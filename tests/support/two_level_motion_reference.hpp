#pragma once
// The reference of the two-level motion-blur tests (CPU and GPU): the world triangles of a blurred
// frame at one shutter fraction computed from the scene alone (docs/motion-blur.md, "Two-level
// scenes": key matrices in float lerped entry by entry, each key's positions at its local time
// lerped, the product in double), a ray's nearest hit among them in double, and rays aimed at them.
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "anim/scene.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/scene/two_level.hpp"

namespace tsah::test {

// The world triangles of a blurred two-level frame at shutter fraction tau, computed from the scene
// alone by the stated rule: key matrices worldAt(key) in float lerped entry by entry, the source's
// positions at each key's local time lerped (motion::lerpVertex), the product in double.
struct WorldAt {
  std::vector<std::vector<double>> positions;  // per instance: 3 doubles per vertex
};

inline WorldAt worldTriangles(const TwoLevelScene& scene, std::span<const double> keys, float tau) {
  const anim::SceneSources& s = scene.scene;
  std::vector<float> fractions = motion::keyFractions(keys);
  const motion::Segment seg = motion::segmentAt(fractions.data(), int(fractions.size()), tau);
  const std::size_t k0 = std::size_t(seg.index), k1 = keys.size() > 1 ? k0 + 1 : k0;
  WorldAt out;
  for (const anim::SceneSourceInstance& instance : s.instances) {
    const anim::Animation& source = s.sourceOf(instance);
    const anim::Matrix4 w0 = instance.worldAt(keys[k0]), w1 = instance.worldAt(keys[k1]);
    float m[12];
    for (int e = 0; e < 12; ++e) m[e] = motion::lerp(float(w0[e]), float(w1[e]), seg.f);
    const std::vector<float> p0 = source.positionsAt(instance.localTime(keys[k0], source));
    const std::vector<float> p1 = source.positionsAt(instance.localTime(keys[k1], source));
    std::vector<double> world(p0.size());
    for (std::size_t v = 0; v < source.vertexCount(); ++v) {
      const Vec3 p = motion::lerpVertex({p0[3 * v], p0[3 * v + 1], p0[3 * v + 2]},
                                        {p1[3 * v], p1[3 * v + 1], p1[3 * v + 2]}, seg.f);
      for (int r = 0; r < 3; ++r)
        world[3 * v + r] = double(m[4 * r]) * p.x + double(m[4 * r + 1]) * p.y + double(m[4 * r + 2]) * p.z + double(m[4 * r + 3]);
    }
    out.positions.push_back(std::move(world));
  }
  return out;
}

// Möller-Trumbore in double: t in (tmin, tmax) or -1.
inline double intersectDouble(const Ray& ray, const double* a, const double* b, const double* c) {
  const double o[3] = {ray.org.x, ray.org.y, ray.org.z}, d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
  double e1[3], e2[3], s[3];
  for (int i = 0; i < 3; ++i) {
    e1[i] = b[i] - a[i];
    e2[i] = c[i] - a[i];
    s[i] = o[i] - a[i];
  }
  const double p[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]};
  const double det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
  if (det == 0.0) return -1.0;
  const double u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) / det;
  const double q[3] = {s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]};
  const double v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) / det;
  const double t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) / det;
  if (u < 0.0 || v < 0.0 || u + v > 1.0 || !(t > ray.tmin && t < ray.tmax)) return -1.0;
  return t;
}

struct Reference {
  uint32_t instance = kNoHit, prim = kNoHit;
  double t = -1.0;
  bool valid() const { return instance != kNoHit; }
};

inline double triangleT(const TwoLevelScene& scene, const WorldAt& world, const Ray& ray, uint32_t i, uint32_t tri) {
  const uint32_t* v = scene.scene.sourceOf(scene.scene.instances[i]).indices().data() + 3 * std::size_t(tri);
  const std::vector<double>& p = world.positions[i];
  return intersectDouble(ray, &p[3 * v[0]], &p[3 * v[1]], &p[3 * v[2]]);
}

inline Reference bruteForce(const TwoLevelScene& scene, const WorldAt& world, const Ray& ray) {
  Reference best;
  for (uint32_t i = 0; i < scene.instanceCount(); ++i)
    for (uint32_t tri = 0; tri < scene.scene.sourceOf(scene.scene.instances[i]).triangleCount(); ++tri) {
      const double t = triangleT(scene, world, ray, i, tri);
      if (t > 0.0 && (!best.valid() || t < best.t)) best = {i, tri, t};
    }
  return best;
}

// Rays from random points around the scene at the centroid of a random triangle at the ray's time.
inline Ray rayAtCentroid(const TwoLevelScene& scene, const WorldAt& world, const Aabb& bounds, std::mt19937& rng) {
  std::uniform_int_distribution<uint32_t> pickInstance(0, scene.instanceCount() - 1);
  const uint32_t i = pickInstance(rng);
  const anim::Animation& source = scene.scene.sourceOf(scene.scene.instances[i]);
  std::uniform_int_distribution<uint32_t> pickTri(0, source.triangleCount() - 1);
  const uint32_t* v = source.indices().data() + 3 * std::size_t(pickTri(rng));
  double c[3] = {0, 0, 0};
  for (int k = 0; k < 3; ++k)
    for (int a = 0; a < 3; ++a) c[a] += world.positions[i][3 * v[k] + a] / 3.0;
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const Vec3 e = bounds.extent();
  Ray ray;
  ray.org = {bounds.lo.x + e.x * (2 * unit(rng) - 0.5f), bounds.lo.y + e.y * (2 * unit(rng) - 0.5f),
             bounds.lo.z + e.z * (2 * unit(rng) - 0.5f)};
  ray.dir = Vec3{float(c[0]), float(c[1]), float(c[2])} - ray.org;  // t = 1 near the centroid
  ray.tmin = 0.0f;
  ray.tmax = 1e30f;
  return ray;
}

}  // namespace tsah::test
