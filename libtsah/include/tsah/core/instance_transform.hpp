#pragma once
// The two-level runtimes' instance transforms, on the CPU and on the GPU alike (the CPU's and the
// device's boxes and hits must be equal bit for bit): a ray moved into instance space, and the box
// of an affine image of a box.
#include <cmath>
#include <cstddef>

#if !defined(__CUDACC__) && (defined(__SSE2__) || defined(_M_X64))
#include <emmintrin.h>
#define TSAH_INSTANCE_SSE 1
#endif

#include "tsah/core/aabb.hpp"
#include "tsah/core/ray.hpp"

namespace tsah {

// A 3x4 affine map in float, row-major (world -> instance space at TLAS leaves).
struct Affine3x4 {
  float m[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  TSAH_HD Vec3 point(const Vec3& p) const {
    return {m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
            m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]};
  }
  TSAH_HD Vec3 vector(const Vec3& d) const {
    return {m[0] * d.x + m[1] * d.y + m[2] * d.z, m[4] * d.x + m[5] * d.y + m[6] * d.z,
            m[8] * d.x + m[9] * d.y + m[10] * d.z};
  }
};

// The ray in instance space: origin by the map, direction by its linear part (not normalized, so
// distances along it stay the world ray's), up to tmax.
TSAH_HD Ray rayInInstance(const Affine3x4& toInstance, const Ray& ray, float tmax) {
  Ray local = ray;
  local.org = toInstance.point(ray.org);
  local.dir = toInstance.vector(ray.dir);
  local.tmax = tmax;
  return local;
}

// rayInInstance as the CPU runs it: on x86-64 with SSE, the map's columns scaled by the origin's
// and the direction's coordinates, lane by lane in rayInInstance's order ((c0 x + c1 y) + c2 z) + c3,
// so the same bits (the GPU's hits must equal the CPU's). The scalar form, compiled for baseline
// x86-64, shuffled lanes to and fro: 26 instructions more per instance a two-level trace enters.
inline Ray rayInInstanceHost(const Affine3x4& toInstance, const Ray& ray, float tmax) {
#ifdef TSAH_INSTANCE_SSE
  static_assert(offsetof(Ray, tmin) == 12 && offsetof(Ray, dir) == 16 && offsetof(Ray, tmax) == 28);
  __m128 c0 = _mm_loadu_ps(toInstance.m), c1 = _mm_loadu_ps(toInstance.m + 4), c2 = _mm_loadu_ps(toInstance.m + 8);
  __m128 c3 = _mm_setzero_ps();
  _MM_TRANSPOSE4_PS(c0, c1, c2, c3);  // the rows become the columns: c3 is the translation
  const float* r = reinterpret_cast<const float*>(&ray);  // org x y z, tmin, dir x y z, tmax
  const __m128 org = _mm_add_ps(
      _mm_add_ps(_mm_add_ps(_mm_mul_ps(c0, _mm_set1_ps(r[0])), _mm_mul_ps(c1, _mm_set1_ps(r[1]))),
                 _mm_mul_ps(c2, _mm_set1_ps(r[2]))),
      c3);
  const __m128 dir = _mm_add_ps(_mm_add_ps(_mm_mul_ps(c0, _mm_set1_ps(r[4])), _mm_mul_ps(c1, _mm_set1_ps(r[5]))),
                                _mm_mul_ps(c2, _mm_set1_ps(r[6])));
  Ray local;  // stored as two vectors, then the limits over their fourth lanes
  float* out = reinterpret_cast<float*>(&local);
  _mm_storeu_ps(out, org);
  _mm_storeu_ps(out + 4, dir);
  local.tmin = ray.tmin;
  local.tmax = tmax;
  return local;
#else
  return rayInInstance(toInstance, ray, tmax);
#endif
}

// A point moved by rows (the 3x4 affine map, row-major, in double) and rounded to float: what
// anim::transformPoints computes for the baked scene's vertices.
TSAH_HD Vec3 transformPointRows(const double* rows, const Vec3& point) {
  const double p[3] = {point.x, point.y, point.z};
  float q[3];
  for (int r = 0; r < 3; ++r)
    q[r] = float(rows[4 * r] * p[0] + rows[4 * r + 1] * p[1] + rows[4 * r + 2] * p[2] + rows[4 * r + 3]);
  return {q[0], q[1], q[2]};
}

// rows: the 3x4 affine map, row-major (x' = rows[0..3] . (x, y, z, 1), and so on). Each of the box's
// 8 corners is transformed in double and rounded to float, then widened by one ulp outward: the
// float box contains the float points that rays transformed into instance space are tested against.
// An empty box stays empty.
TSAH_HD Aabb transformBoxRows(const Aabb& box, const double* rows) {
  if (box.empty()) return box;
  Aabb out;
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3 q = transformPointRows(rows, {(corner & 1) ? box.hi.x : box.lo.x, (corner & 2) ? box.hi.y : box.lo.y,
                                             (corner & 4) ? box.hi.z : box.lo.z});
    out.extend(Vec3{nextafterf(q.x, -3.4e38f), nextafterf(q.y, -3.4e38f), nextafterf(q.z, -3.4e38f)});
    out.extend(Vec3{nextafterf(q.x, 3.4e38f), nextafterf(q.y, 3.4e38f), nextafterf(q.z, 3.4e38f)});
  }
  return out;
}

// The inverse of the affine map m (3x4 rows, row-major, in double) into inv (3x4 rows): the linear
// part by cofactors, then -L^-1 * translation. False (inv untouched) when the linear part's
// determinant is 0 or not finite. The CPU and the GPU two-level runtimes share it so that a blurred
// instance's lerped map is inverted to the same bits on both (no fused multiply-adds on either side).
TSAH_HD bool invertAffineRows(const double* m, double* inv) {
  const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
  const double det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g);
  if (!(det != 0.0) || !(det - det == 0.0)) return false;  // 0, infinite or NaN
  const double r = 1.0 / det;
  inv[0] = (e * i - f * h) * r;
  inv[1] = (c * h - b * i) * r;
  inv[2] = (b * f - c * e) * r;
  inv[4] = (f * g - d * i) * r;
  inv[5] = (a * i - c * g) * r;
  inv[6] = (c * d - a * f) * r;
  inv[8] = (d * h - e * g) * r;
  inv[9] = (b * g - a * h) * r;
  inv[10] = (a * e - b * d) * r;
  for (int row = 0; row < 3; ++row)
    inv[4 * row + 3] = -(inv[4 * row] * m[3] + inv[4 * row + 1] * m[7] + inv[4 * row + 2] * m[11]);
  return true;
}

// World -> instance space of a float instance -> world map: its entries exactly in double, inverted
// (invertAffineRows), rounded to float. False when the map is singular: the instance is flat then.
TSAH_HD bool instanceSpaceOfRows(const Affine3x4& toWorld, Affine3x4& space) {
  double m[12], inv[12];
  for (int i = 0; i < 12; ++i) m[i] = double(toWorld.m[i]);
  if (!invertAffineRows(m, inv)) return false;
  for (int i = 0; i < 12; ++i) space.m[i] = float(inv[i]);
  return true;
}

}  // namespace tsah
