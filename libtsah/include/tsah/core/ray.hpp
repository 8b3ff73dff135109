#pragma once
// Rays, hits and the ray-box slab test shared by the CPU and CUDA runtimes.
#include <cmath>
#include <cstdint>
#include <type_traits>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"

namespace tsah {

inline constexpr uint32_t kNoHit = 0xffffffffu;

struct Ray {
  Vec3 org;
  float tmin;
  Vec3 dir;  // need not be normalized; t is measured in units of dir
  float tmax;
};

// A closest hit: the triangle id (of the animation, not the slot) and barycentric coordinates,
// point = (1 - u - v) * v0 + u * v1 + v * v2.
struct Hit {
  float t = 0.0f;
  float u = 0.0f, v = 0.0f;
  uint32_t tri = kNoHit;

  TSAH_HD bool valid() const { return tri != kNoHit; }
};

static_assert(sizeof(Ray) == 32 && alignof(Ray) == 4 && std::is_trivially_copyable_v<Ray>);
static_assert(sizeof(Hit) == 16 && alignof(Hit) == 4 && std::is_trivially_copyable_v<Hit>);

// Per-ray values reused by every box and triangle test of one traversal.
struct RayPrep {
  Vec3 org;
  Vec3 invDir;  // 1/dir with zero components replaced by a tiny signed value (no NaN in the slabs)
  // Watertight triangle test (Woop, Benthin, Wald 2013): the axis of the largest direction component
  // becomes z, and the shear that maps the ray onto +z.
  int kx, ky, kz;
  float sx, sy, sz;
};

TSAH_HD float absf(float x) { return x < 0.0f ? -x : x; }

// The slab part of RayPrep (org, invDir): all the box tests need.
TSAH_HD RayPrep prepareSlabs(const Ray& ray) {
  RayPrep p;
  p.org = ray.org;
  for (int a = 0; a < 3; ++a) {
    float d = ray.dir[a];
    // fabs, not absf: the same comparison for every d (-0 and NaN included), without absf's
    // branch on the sign, which a random direction mispredicts half the time.
    if (std::fabs(d) < 1e-30f) d = d < 0.0f ? -1e-30f : 1e-30f;
    p.invDir[a] = 1.0f / d;
  }
  return p;
}

// The watertight part of RayPrep (kx, ky, kz, sx, sy, sz): only the watertight triangle test reads
// it, so a traversal that rarely runs that test may fill it in on first use.
TSAH_HD void prepareShear(const Ray& ray, RayPrep& p) {
  const float ax = absf(ray.dir.x), ay = absf(ray.dir.y), az = absf(ray.dir.z);
  p.kz = ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
  p.kx = p.kz == 2 ? 0 : p.kz + 1;
  p.ky = p.kx == 2 ? 0 : p.kx + 1;
  if (ray.dir[p.kz] < 0.0f) {  // keep the winding: swap x and y for a negative z direction
    const int k = p.kx;
    p.kx = p.ky;
    p.ky = k;
  }
  p.sx = ray.dir[p.kx] / ray.dir[p.kz];
  p.sy = ray.dir[p.ky] / ray.dir[p.kz];
  p.sz = 1.0f / ray.dir[p.kz];
}

TSAH_HD RayPrep prepareRay(const Ray& ray) {
  RayPrep p = prepareSlabs(ray);
  prepareShear(ray, p);
  return p;
}

// 1 + 2*gamma(3) (Ize 2013): widening the far slab distance by this factor makes the box test
// conservative under float rounding, so no hit a watertight triangle test would find is culled.
inline constexpr float kSlabFarScale = 1.0000004f;

TSAH_HD float fminf_(float a, float b) { return a < b ? a : b; }
TSAH_HD float fmaxf_(float a, float b) { return a > b ? a : b; }

// Slab test against box b on [tmin, tmax]; returns the entry distance in tEntry.
TSAH_HD bool intersectBox(const RayPrep& r, const Aabb& b, float tmin, float tmax, float& tEntry) {
  const float x0 = (b.lo.x - r.org.x) * r.invDir.x, x1 = (b.hi.x - r.org.x) * r.invDir.x;
  const float y0 = (b.lo.y - r.org.y) * r.invDir.y, y1 = (b.hi.y - r.org.y) * r.invDir.y;
  const float z0 = (b.lo.z - r.org.z) * r.invDir.z, z1 = (b.hi.z - r.org.z) * r.invDir.z;
  const float tn = fmaxf_(fmaxf_(fminf_(x0, x1), fminf_(y0, y1)), fmaxf_(fminf_(z0, z1), tmin));
  const float tf = fminf_(fminf_(fmaxf_(x0, x1), fmaxf_(y0, y1)), fminf_(fmaxf_(z0, z1), tmax)) * kSlabFarScale;
  tEntry = tn;
  return tn <= tf;
}

}  // namespace tsah
