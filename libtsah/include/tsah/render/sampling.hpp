#pragma once
// Deterministic per-sample random numbers and the sample warps the renderers use. A sample's
// numbers are a hash of (seed, frame, pixel, sample, dimension), so images do not depend on the
// thread count or the order in which pixels are processed, and the CPU and GPU runtimes can draw
// the same numbers. The float functions (sqrtf, cosf, sinf) are the C library's on the host and
// CUDA's on the device: sqrtf is correctly rounded on both, cosf/sinf may differ in the last bit.
#include <cmath>
#include <cstdint>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/ray.hpp"  // fmaxf_

namespace tsah {

// A 32-bit integer hash with good avalanche (the "lowbias32" constants of C. Wellons).
TSAH_HD uint32_t hash32(uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352dU;
  x ^= x >> 15;
  x *= 0x846ca68bU;
  x ^= x >> 16;
  return x;
}

struct SampleKey {
  uint32_t seed, frame, pixel;
};

// Uniform float in [0, 1) for (key, sample, dimension).
TSAH_HD float sampleUniform(const SampleKey& key, uint32_t sample, uint32_t dimension) {
  uint32_t h = hash32(key.seed ^ 0x9e3779b9U);
  h = hash32(h ^ key.frame);
  h = hash32(h ^ key.pixel);
  h = hash32(h ^ (sample * 0x632be5abU + dimension));
  return float(h >> 8) * (1.0f / 16777216.0f);
}

// The camera-sample time of a pixel in a motion-blurred frame, a fraction of the shutter in
// [0, 1) shared by the pixel's primary, ambient-occlusion and shadow rays. The golden-ratio (R1)
// sequence over the pixel index, rotated by a hash of (seed, frame): any n consecutive pixels
// spread their times over the shutter with gaps of at most ~2.6/n (stratified, unlike independent
// random times), and the same seed and frame give the same times. Computed in 32-bit fixed point,
// so host and device produce the same float.
TSAH_HD float pixelShutterTime(const SampleKey& key) {
  const uint32_t rotation = hash32(hash32(key.seed ^ 0x85ebca6bU) ^ key.frame);
  const uint32_t position = rotation + key.pixel * 0x9e3779b9U;  // 2^32 / golden ratio
  return float(position >> 8) * (1.0f / 16777216.0f);
}

// v / |v| with an IEEE square root and division on host and device alike (CUDA's rsqrtf would
// round differently), so CPU and GPU renderers compute the same directions; (0, 0, 1) for a zero
// or non-finite length.
TSAH_HD Vec3 normalize(Vec3 v) {
  const float len2 = dot(v, v);
  if (!(len2 > 0.0f)) return {0.0f, 0.0f, 1.0f};
  return v * (1.0f / sqrtf(len2));
}

// An orthonormal basis (t, b, n) around unit vector n (Duff et al. 2017, branchless).
TSAH_HD void orthonormalBasis(Vec3 n, Vec3& t, Vec3& b) {
  const float sign = n.z >= 0.0f ? 1.0f : -1.0f;
  const float a = -1.0f / (sign + n.z);
  const float c = n.x * n.y * a;
  t = {1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x};
  b = {c, sign + n.y * n.y * a, -n.y};
}

// Cosine-weighted direction in the hemisphere around unit normal n (Malley: a uniform disk point
// lifted onto the hemisphere; concentric mapping keeps strata compact).
TSAH_HD Vec3 cosineHemisphere(Vec3 n, float u1, float u2) {
  const float a = 2.0f * u1 - 1.0f, b = 2.0f * u2 - 1.0f;
  float r = 0.0f, phi = 0.0f;
  constexpr float kPi4 = 0.78539816339f;
  if (a != 0.0f || b != 0.0f) {
    if (a * a > b * b) {
      r = a;
      phi = kPi4 * (b / a);
    } else {
      r = b;
      phi = 2.0f * kPi4 - kPi4 * (a / b);
    }
  }
  const float x = r * cosf(phi), y = r * sinf(phi);
  const float z = sqrtf(fmaxf_(0.0f, 1.0f - x * x - y * y));
  Vec3 t, bt;
  orthonormalBasis(n, t, bt);
  return t * x + bt * y + n * z;
}

// Uniform point on a disk of radius r around c, perpendicular to unit vector axis.
TSAH_HD Vec3 sampleDisk(Vec3 c, Vec3 axis, float r, float u1, float u2) {
  Vec3 t, b;
  orthonormalBasis(axis, t, b);
  const float rad = r * sqrtf(u1);
  const float phi = 6.28318530718f * u2;
  return c + t * (rad * cosf(phi)) + b * (rad * sinf(phi));
}

}  // namespace tsah
