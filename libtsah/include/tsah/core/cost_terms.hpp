#pragma once
// The arithmetic of the paper's cost model (Section 4) as plain functions on plain data, shared by
// the sequential insertion optimizer, the parallel reinsertion optimizer, the cost evaluation
// (cost.cpp) and CUDA kernels (TSAH_HD), so that every optimizer agrees on what a cost is.
//
//   Eq. 1   C_i  = (cT * sum_inner S_N(i) + cI * sum_leaves j_N * S_N(i)) / S_i
//   Eq. 3   C~^k = sum_i C_i^(k+1) / sum_i C_i^k
//   A(B)    = sum_i areaFactor_i * area(B_i),  areaFactor_i = (w_i / W) / S_i,  w_i = C_i^k
//
// While the weights are fixed (one optimizer batch or round), the interior part of C~^0, and to
// first order of C~^k, is cT times the sum of A over interior nodes: every cost a search compares is
// a weighted multi-frame area A. A node keeps one box per representative frame, contiguously.
#include <cstdint>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"

// SSE2 (every x86-64 host compiler) computes the union areas 4 lanes at a time; TSAH_SCALAR_SEARCH,
// another architecture or device code takes the plain loop.
#if defined(__SSE2__) && !defined(TSAH_SCALAR_SEARCH) && !defined(__CUDA_ARCH__)
#define TSAH_SSE_COST_TERMS 1
#include <immintrin.h>
#endif

namespace tsah::cost {

// x^k for a small non-negative integer k, by squaring (std::pow is far slower, and this runs after
// every optimizer step).
TSAH_HD double integerPower(double x, int k) {
  double result = 1.0;
  while (k > 0) {
    if (k & 1) result *= x;
    x *= x;
    k >>= 1;
  }
  return result;
}

// Eq. 1 from the per-frame sums. A frame whose root box has no area has no meaningful area ratios:
// its cost is the limit of a uniformly shrinking scene, where every ray that reaches the root visits
// every node, cT * inner + cI * primitives.
TSAH_HD double frameCost(float ct, float ci, double innerAreaSum, double leafAreaSum, double rootArea,
                         uint64_t innerCount, uint64_t primCount) {
  if (!(rootArea > 0.0)) return double(ct) * double(innerCount) + double(ci) * double(primCount);
  return (double(ct) * innerAreaSum + double(ci) * leafAreaSum) / rootArea;
}

// Eq. 3 of `count` frame costs (k >= 0; 0 for no frames). Scaled by the largest cost so that C^k
// cannot overflow for large k; the ratio is unchanged.
TSAH_HD double temporalCost(const double* frameCosts, uint32_t count, int k) {
  if (count == 0) return 0.0;
  double largest = 0.0;
  for (uint32_t i = 0; i < count; ++i) largest = frameCosts[i] > largest ? frameCosts[i] : largest;
  if (!(largest > 0.0)) return 0.0;
  if (k == 0) {
    double sum = 0.0;
    for (uint32_t i = 0; i < count; ++i) sum += frameCosts[i];
    return sum / double(count);
  }
  double numerator = 0.0, denominator = 0.0;
  for (uint32_t i = 0; i < count; ++i) {
    const double x = frameCosts[i] / largest;
    const double xk = integerPower(x, k);
    numerator += xk * x;
    denominator += xk;
  }
  return denominator > 0.0 ? largest * numerator / denominator : 0.0;
}

// The area factor of one frame: normalized weight over root area (0 for a frame with no root area).
TSAH_HD float areaFactor(double normalizedWeight, double rootArea) {
  return rootArea > 0.0 ? float(normalizedWeight / rootArea) : 0.0f;
}

// A(B) of one node's boxes (one per frame).
TSAH_HD float weightedArea(const Aabb* boxes, const float* areaFactor, uint32_t frames) {
  float sum = 0.0f;
  for (uint32_t f = 0; f < frames; ++f) sum += areaFactor[f] * boxes[f].area();
  return sum;
}

// Surface area of the union of two boxes, without building the union box first.
TSAH_HD float unionArea(const Aabb& a, const Aabb& b) {
  const float dx = (a.hi.x > b.hi.x ? a.hi.x : b.hi.x) - (a.lo.x < b.lo.x ? a.lo.x : b.lo.x);
  const float dy = (a.hi.y > b.hi.y ? a.hi.y : b.hi.y) - (a.lo.y < b.lo.y ? a.lo.y : b.lo.y);
  const float dz = (a.hi.z > b.hi.z ? a.hi.z : b.hi.z) - (a.lo.z < b.lo.z ? a.lo.z : b.lo.z);
  return 2.0f * (dx * dy + dy * dz + dz * dx);
}

// A(a ∪ b) in plain float arithmetic, frame after frame: the same bits on the host and on the GPU
// (built without fused multiply-adds), so that the GPU optimizer and its host emulation agree.
TSAH_HD float weightedUnionAreaPortable(const Aabb* a, const Aabb* b, const float* areaFactor, uint32_t frames) {
  float sum = 0.0f;
  for (uint32_t f = 0; f < frames; ++f) sum += areaFactor[f] * unionArea(a[f], b[f]);
  return sum;
}

// A(a ∪ b) for two nodes' boxes (one per frame each): the innermost operation of every search.
TSAH_HD float weightedUnionArea(const Aabb* a, const Aabb* b, const float* areaFactor, uint32_t frames) {
#if defined(TSAH_SSE_COST_TERMS)
  // One frame per iteration: lanes [x y z -]; the lo corner is loaded from lo.x, the hi corner from
  // lo.z and shifted down one lane, so no load leaves the box. Lane 3 carries no area and is dropped.
  const float* pa = &a[0].lo.x;
  const float* pb = &b[0].lo.x;
  __m128 sum = _mm_setzero_ps();
  for (uint32_t f = 0; f < frames; ++f, pa += 6, pb += 6) {
    const __m128 lo = _mm_min_ps(_mm_loadu_ps(pa), _mm_loadu_ps(pb));
    const __m128 hiShifted = _mm_max_ps(_mm_loadu_ps(pa + 2), _mm_loadu_ps(pb + 2));  // [lo.z hx hy hz]
    const __m128 hi = _mm_shuffle_ps(hiShifted, hiShifted, _MM_SHUFFLE(0, 3, 2, 1));  // [hx hy hz lo.z]
    const __m128 d = _mm_sub_ps(hi, lo);
    const __m128 rotated = _mm_shuffle_ps(d, d, _MM_SHUFFLE(3, 0, 2, 1));  // dy dz dx
    sum = _mm_add_ps(sum, _mm_mul_ps(_mm_mul_ps(d, rotated), _mm_set1_ps(areaFactor[f])));
  }
  alignas(16) float lanes[4];
  _mm_store_ps(lanes, sum);
  return 2.0f * (lanes[0] + lanes[1] + lanes[2]);
#else
  return weightedUnionAreaPortable(a, b, areaFactor, frames);
#endif
}

}  // namespace tsah::cost
