#pragma once
// Triangle intersection shared by the CPU and CUDA runtimes.
//
// Fast path: Woop's unit-triangle transform as used by Aila & Laine (48 bytes per triangle,
// recomputed every frame): one dot product gives the hit distance, two more the barycentrics.
// That test alone is not watertight: rounding can let a ray slip between two triangles sharing an
// edge. So whenever the fast path lands within kWoopEdgeBand of an edge (either side), the
// watertight test of Woop, Benthin and Wald (2013) on the triangle's vertices decides instead.
// Near edges the result is therefore exactly the watertight one, and elsewhere the two tests agree
// (their barycentric error is far below the band). Closest-hit and any-hit use the same function,
// so they always agree on whether there is a hit.
#include <cstdint>
#include <type_traits>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/ray.hpp"

namespace tsah {

struct alignas(16) Float4 {
  float x, y, z, w;
};

// Rows of the affine map from world space to the triangle's unit space (Aila–Laine's layout):
//   r0: (n / |n|^2,        dot(n, v2) / |n|^2)   -> t  = (r0.w - dot(o, r0.xyz)) / dot(d, r0.xyz)
//   r1: (e1 x n / |n|^2,  -dot(e1 x n, v2) / |n|^2) -> b0 = r1.w + dot(p, r1.xyz)  (weight of v0)
//   r2: (n x e0 / |n|^2,  -dot(n x e0, v2) / |n|^2) -> b1 = r2.w + dot(p, r2.xyz)  (weight of v1)
// with e0 = v0 - v2, e1 = v1 - v2, n = e0 x e1. A degenerate triangle gets all-zero rows, for which
// the distance is NaN and the test never reports a hit.
struct WoopTriangle {
  Float4 r0, r1, r2;
};

static_assert(sizeof(Float4) == 16 && alignof(Float4) == 16);
static_assert(sizeof(WoopTriangle) == 48 && alignof(WoopTriangle) == 16);
static_assert(std::is_trivially_copyable_v<WoopTriangle> && std::is_standard_layout_v<WoopTriangle>);

// The Woop rows of triangle (v0, v1, v2) in double precision, before rounding to float: rows[4r + c]
// is component c of row r, and |n|^2 (the triangle is degenerate unless 1e-300 < |n|^2 <
// 1e300) in nn. D is double, or a vector of doubles (GCC vector extension): the same operations lane by
// lane, so a refit that computes several triangles at once gets the same bits as one at a time.
template <class D>
TSAH_HD void woopRowsDouble(const D v0[3], const D v1[3], const D v2[3], D rows[12], D& nn) {
  const D e0[3] = {v0[0] - v2[0], v0[1] - v2[1], v0[2] - v2[2]};
  const D e1[3] = {v1[0] - v2[0], v1[1] - v2[1], v1[2] - v2[2]};
  const D n[3] = {e0[1] * e1[2] - e0[2] * e1[1], e0[2] * e1[0] - e0[0] * e1[2], e0[0] * e1[1] - e0[1] * e1[0]};
  nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  const D inv = 1.0 / nn;
  const D a[3] = {(e1[1] * n[2] - e1[2] * n[1]) * inv, (e1[2] * n[0] - e1[0] * n[2]) * inv,
                  (e1[0] * n[1] - e1[1] * n[0]) * inv};  // e1 x n
  const D b[3] = {(n[1] * e0[2] - n[2] * e0[1]) * inv, (n[2] * e0[0] - n[0] * e0[2]) * inv,
                  (n[0] * e0[1] - n[1] * e0[0]) * inv};  // n x e0
  const D c[3] = {n[0] * inv, n[1] * inv, n[2] * inv};
  for (int k = 0; k < 3; ++k) {
    rows[k] = c[k];
    rows[4 + k] = a[k];
    rows[8 + k] = b[k];
  }
  rows[3] = c[0] * v2[0] + c[1] * v2[1] + c[2] * v2[2];
  rows[7] = -(a[0] * v2[0] + a[1] * v2[1] + a[2] * v2[2]);
  rows[11] = -(b[0] * v2[0] + b[1] * v2[1] + b[2] * v2[2]);
}

// False for a degenerate (or NaN) triangle, whose rows must be all zero.
TSAH_HD bool woopNondegenerate(double nn) { return nn > 1e-300 && nn < 1e300; }

// Computed in double precision, then rounded, so the rows are as accurate as float allows.
TSAH_HD WoopTriangle makeWoopTriangle(Vec3 v0, Vec3 v1, Vec3 v2) {
  const double p0[3] = {v0.x, v0.y, v0.z}, p1[3] = {v1.x, v1.y, v1.z}, p2[3] = {v2.x, v2.y, v2.z};
  double r[12], nn;
  woopRowsDouble(p0, p1, p2, r, nn);
  WoopTriangle w{{0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0}};
  if (!woopNondegenerate(nn)) return w;  // degenerate (or NaN): never hit
  w.r0 = {float(r[0]), float(r[1]), float(r[2]), float(r[3])};
  w.r1 = {float(r[4]), float(r[5]), float(r[6]), float(r[7])};
  w.r2 = {float(r[8]), float(r[9]), float(r[10]), float(r[11])};
  return w;
}

// Barycentric band around the edges in which the watertight test decides: at least kWoopEdgeBand,
// wider where the rounding error of the fast path may be larger (kWoopErrorScale times a running
// bound of the magnitudes involved, i.e. 64 float ulps of them).
inline constexpr float kWoopEdgeBand = 1e-5f;
inline constexpr float kWoopErrorScale = 64.0f * 5.96e-8f;

// Watertight ray-triangle test (Woop, Benthin, Wald, JCGT 2013), no backface culling. On a hit
// within (tmin, tmax) sets t and the weights u (of v1) and v (of v2) and returns true.
TSAH_HD bool intersectWatertight(const RayPrep& r, Vec3 v0, Vec3 v1, Vec3 v2, float tmin, float tmax, float& t,
                                 float& u, float& v) {
  const Vec3 a = v0 - r.org, b = v1 - r.org, c = v2 - r.org;
  const float ax = a[r.kx] - r.sx * a[r.kz], ay = a[r.ky] - r.sy * a[r.kz];
  const float bx = b[r.kx] - r.sx * b[r.kz], by = b[r.ky] - r.sy * b[r.kz];
  const float cx = c[r.kx] - r.sx * c[r.kz], cy = c[r.ky] - r.sy * c[r.kz];
  float U = cx * by - cy * bx;
  float V = ax * cy - ay * cx;
  float W = bx * ay - by * ax;
  if (U == 0.0f || V == 0.0f || W == 0.0f) {  // on an edge in float: decide in double
    U = float(double(cx) * double(by) - double(cy) * double(bx));
    V = float(double(ax) * double(cy) - double(ay) * double(cx));
    W = float(double(bx) * double(ay) - double(by) * double(ax));
  }
  if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return false;
  const float det = U + V + W;
  if (det == 0.0f) return false;
  const float az = r.sz * a[r.kz], bz = r.sz * b[r.kz], cz = r.sz * c[r.kz];
  const float T = U * az + V * bz + W * cz;
  const float rcp = 1.0f / det;
  const float tt = T * rcp;
  if (!(tt > tmin && tt < tmax)) return false;
  t = tt;
  u = V * rcp;
  v = W * rcp;
  return true;
}

// Woop fast path with the watertight fallback near edges (see the top of this file). The vertices
// are only read in the fallback.
template <typename VertexFetch>
TSAH_HD bool intersectTriangle(const Ray& ray, const RayPrep& prep, const WoopTriangle& w, float tmax,
                               VertexFetch&& fetchVertices, float& t, float& u, float& v) {
  const float oz = w.r0.w - (ray.org.x * w.r0.x + ray.org.y * w.r0.y + ray.org.z * w.r0.z);
  const float dz = ray.dir.x * w.r0.x + ray.dir.y * w.r0.y + ray.dir.z * w.r0.z;
  const float tt = oz / dz;
  if (!(tt > ray.tmin && tt < tmax)) {
    // A degenerate triangle (NaN here) is also a miss for the watertight test (zero determinant),
    // but a ray nearly parallel to the plane needs the exact test.
    if (!(absf(dz) < 1e-12f * (absf(w.r0.x) + absf(w.r0.y) + absf(w.r0.z)))) return false;
  } else {
    // Barycentrics and a bound on their rounding error (sum of the magnitudes of the terms, with
    // the error of t carried through), so the band grows for grazing rays and far origins.
    const float ou = ray.org.x * w.r1.x + ray.org.y * w.r1.y + ray.org.z * w.r1.z;
    const float du = ray.dir.x * w.r1.x + ray.dir.y * w.r1.y + ray.dir.z * w.r1.z;
    const float ov = ray.org.x * w.r2.x + ray.org.y * w.r2.y + ray.org.z * w.r2.z;
    const float dv = ray.dir.x * w.r2.x + ray.dir.y * w.r2.y + ray.dir.z * w.r2.z;
    const float b0 = w.r1.w + ou + tt * du;
    const float b1 = w.r2.w + ov + tt * dv;
    const float b2 = 1.0f - b0 - b1;
    const float errT = (absf(w.r0.w) + absf(ray.org.x * w.r0.x) + absf(ray.org.y * w.r0.y) + absf(ray.org.z * w.r0.z)) /
                       absf(dz);
    const float e0 = absf(w.r1.w) + absf(ray.org.x * w.r1.x) + absf(ray.org.y * w.r1.y) + absf(ray.org.z * w.r1.z) +
                     absf(tt) * (absf(ray.dir.x * w.r1.x) + absf(ray.dir.y * w.r1.y) + absf(ray.dir.z * w.r1.z)) +
                     errT * absf(du);
    const float e1 = absf(w.r2.w) + absf(ray.org.x * w.r2.x) + absf(ray.org.y * w.r2.y) + absf(ray.org.z * w.r2.z) +
                     absf(tt) * (absf(ray.dir.x * w.r2.x) + absf(ray.dir.y * w.r2.y) + absf(ray.dir.z * w.r2.z)) +
                     errT * absf(dv);
    const float band0 = fmaxf_(kWoopEdgeBand, kWoopErrorScale * e0);
    const float band1 = fmaxf_(kWoopEdgeBand, kWoopErrorScale * e1);
    const float band2 = band0 + band1;
    if (b0 < -band0 || b1 < -band1 || b2 < -band2) return false;
    if (b0 > band0 && b1 > band1 && b2 > band2) {
      t = tt;
      u = b1;
      v = b2;
      return true;
    }
  }
  Vec3 v0, v1, v2;
  fetchVertices(v0, v1, v2);
  return intersectWatertight(prep, v0, v1, v2, ray.tmin, tmax, t, u, v);
}

}  // namespace tsah
