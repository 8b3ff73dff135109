#pragma once
// Float sums, products and fused multiply-adds rounded toward -inf (Down) or +inf (Up), bit for
// bit the same on the CPU and the GPU. On the GPU they are the hardware's rounding modes (one
// instruction each, no slower than round-to-nearest); on the CPU the exact result is formed in
// double (a float product is exact in double, a sum exact up to an error TwoSum recovers) and then
// rounded in the chosen direction. The compressed wide BVH's box test uses them to bound slab
// distances from below and above (cwbvh_layout.hpp), so the host reference traversal takes the same
// decisions as the CUDA kernel.
#include <cmath>
#include <limits>

#include "tsah/core/hd.hpp"

namespace tsah::rounding {

enum class Round { Down, Up };  // toward -inf, toward +inf

namespace detail {

// x rounded in direction R to float, where x = hi + lo exactly (lo: the rounding error of the
// double hi, |lo| <= half an ulp of hi). No float lies strictly between x and hi unless hi is a
// float itself, so only then does lo decide.
template <Round R>
inline float fromDouble(double hi, double lo) {
  constexpr bool up = R == Round::Up;
  float f = static_cast<float>(hi);
  const double back = static_cast<double>(f);
  if (up ? (back < hi || (back == hi && lo > 0.0)) : (back > hi || (back == hi && lo < 0.0)))
    f = std::nextafter(f, (up ? 1.0f : -1.0f) * std::numeric_limits<float>::infinity());
  return f;
}

// Knuth's TwoSum: s + e == a + b exactly (round-to-nearest double, no overflow).
inline void twoSum(double a, double b, double& s, double& e) {
  s = a + b;
  const double bb = s - a;
  e = (a - (s - bb)) + (b - bb);
}

}  // namespace detail

template <Round R>
TSAH_HD float sub(float a, float b) {
#if defined(__CUDA_ARCH__)
  if constexpr (R == Round::Down) return __fsub_rd(a, b);
  else return __fsub_ru(a, b);
#else
  double s, e;
  detail::twoSum(a, -static_cast<double>(b), s, e);
  return detail::fromDouble<R>(s, e);
#endif
}

template <Round R>
TSAH_HD float mul(float a, float b) {
#if defined(__CUDA_ARCH__)
  if constexpr (R == Round::Down) return __fmul_rd(a, b);
  else return __fmul_ru(a, b);
#else
  return detail::fromDouble<R>(static_cast<double>(a) * b, 0.0);  // 48-bit product: exact
#endif
}

// a * b + c with one rounding, for |a| < 2^25 with at most 24 significant bits (a * b is then exact
// in double; the cwbvh box test passes 2^23 + an 8-bit grid coordinate, or -2^23).
template <Round R>
TSAH_HD float fma(float a, float b, float c) {
#if defined(__CUDA_ARCH__)
  if constexpr (R == Round::Down) return __fmaf_rd(a, b, c);
  else return __fmaf_ru(a, b, c);
#else
  double s, e;
  detail::twoSum(static_cast<double>(a) * b, c, s, e);
  return detail::fromDouble<R>(s, e);
#endif
}

TSAH_HD float subDown(float a, float b) { return sub<Round::Down>(a, b); }
TSAH_HD float subUp(float a, float b) { return sub<Round::Up>(a, b); }
TSAH_HD float mulDown(float a, float b) { return mul<Round::Down>(a, b); }
TSAH_HD float mulUp(float a, float b) { return mul<Round::Up>(a, b); }
TSAH_HD float fmaDown(float a, float b, float c) { return fma<Round::Down>(a, b, c); }
TSAH_HD float fmaUp(float a, float b, float c) { return fma<Round::Up>(a, b, c); }

// a + b rounded up, for the quantizer's exact plane checks: addUp(a, b) <= x exactly when the real
// a + b <= x (x a float).
TSAH_HD float addUp(float a, float b) { return subUp(a, -b); }
TSAH_HD float addDown(float a, float b) { return subDown(a, -b); }

// min / max that ignore a NaN operand (IEEE minNum / maxNum: the GPU's FMNMX, std::fmin on the CPU).
TSAH_HD float minNum(float a, float b) {
#if defined(__CUDA_ARCH__)
  return fminf(a, b);
#else
  return std::fmin(a, b);
#endif
}
TSAH_HD float maxNum(float a, float b) {
#if defined(__CUDA_ARCH__)
  return fmaxf(a, b);
#else
  return std::fmax(a, b);
#endif
}

}  // namespace tsah::rounding
