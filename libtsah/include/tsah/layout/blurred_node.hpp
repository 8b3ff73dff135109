#pragma once
// The node record of the GPU's blurred layout (docs/motion-blur.md#the-gpu-node-record): one per
// node and segment (keys s and s + 1), 96 bytes, so that a ray's segment reads a node as three
// 32-byte sectors where two whole key records took four. It holds the node at key s as a
// GpuBvhNode (child boxes pre-padded, motion::prepadBox; references; count0's bit 31 when the
// boxes are the same at every key) and, for each of its 12 box floats, the change to key s + 1 as
// a binary16 value times a power-of-two scale, rounded outward: a lower side's change rounded
// down, an upper side's up. A ray at f takes a + (f * scale) * delta for each side (one fused
// multiply-add), which never lies inside the exact lerp of the two pre-padded keys by more than
// that one rounding, which the pre-pad covers (the proof is in the docs). Host and device share these functions so that
// the tests rebuild every record bit for bit.
#include <cmath>
#include <cstdint>
#if defined(__CUDACC__)
#include <cuda_fp16.h>
#endif

#include "tsah/core/directed_rounding.hpp"
#include "tsah/core/float_bits.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/layout/gpu_layout.hpp"

namespace tsah::motion {

inline constexpr uint32_t kKeysAlikeBit = 0x80000000u;  // in a blurred node record's count0

struct alignas(16) BlurredNodeSegment {
  GpuBvhNode node;      // key s: pre-padded child boxes (rows 0..2) and references (row 3)
  uint16_t delta[12];   // binary16 changes to key s + 1, in the order of the node's 12 box floats
  float scale = 1.0f;   // a power of two: side at key s + 1 >= (lower) or <= (upper) a + scale * delta
  uint32_t unused = 0;
};
static_assert(sizeof(BlurredNodeSegment) == 96 && alignof(BlurredNodeSegment) == 16);

// x (finite) as binary16 bits, rounded toward -infinity (down) or +infinity (up); magnitudes past
// the largest finite binary16 (65504) become it or infinity by the same rule.
TSAH_HD uint16_t halfDirected(float x, bool down) {
  const bool negative = x < 0.0f;
  const float a = negative ? -x : x;
  const bool up = negative ? down : !down;  // round the magnitude up or truncate it
  uint16_t h;
  if (a >= 65504.0f) {
    h = (a > 65504.0f && up) ? 0x7c00u : 0x7bffu;
  } else if (a < 0x1p-14f) {  // binary16 subnormals (and 0): a multiple of 2^-24
    const float units = a * 0x1p24f;  // exact: a power-of-two scale of a float below 2^-14
    const float whole = up ? ceilf(units) : floorf(units);
    h = uint16_t(whole);  // 1024 is the smallest normal's encoding, as it should be
  } else {
    const uint32_t bits = floatBits(a);
    const uint32_t exponent = (bits >> 23) - 127 + 15, mantissa = bits & 0x7fffffu;
    h = uint16_t((exponent << 10) | (mantissa >> 13));
    if (up && (mantissa & 0x1fffu)) ++h;  // a carry into the exponent is the next binade (or inf)
  }
  return uint16_t(h | (negative ? 0x8000u : 0u));
}

// The binary16 value of bits h, exactly (infinities included).
TSAH_HD float halfValue(uint16_t h) {
#if defined(__CUDA_ARCH__)
  return __half2float(__ushort_as_half(h));
#else
  const uint32_t sign = uint32_t(h & 0x8000u) << 16, exponent = (h >> 10) & 0x1fu, mantissa = h & 0x3ffu;
  if (exponent == 0) return bitsFloat(sign | floatBits(float(mantissa) * 0x1p-24f));
  const uint32_t biased = exponent == 31 ? 0xffu : exponent - 15 + 127;
  return bitsFloat(sign | (biased << 23) | (mantissa << 13));
#endif
}

// The record of a node for the segment from key s (atS) to key s + 1 (atNext), both pre-padded.
// Lower sides are the even floats of the box rows, upper sides the odd ones (gpu_layout.hpp).
TSAH_HD BlurredNodeSegment encodeNodeSegment(const GpuBvhNode& atS, const GpuBvhNode& atNext, bool alike) {
  BlurredNodeSegment r;
  r.node = atS;
  if (alike) r.node.count0 |= kKeysAlikeBit;
  const float* a = &atS.c0loX;
  const float* b = &atNext.c0loX;
  // The scale: the largest change below 2^15 in binary16 units (a power of two in [2^-40, 2^127]).
  float largest = 0.0f;
  for (int i = 0; i < 12; ++i) largest = fmaxf(largest, fabsf(b[i] - a[i]));
  int e = -40;
  if (largest > 0.0f) {
    int x;
    (void)frexpf(largest, &x);  // largest < 2^x
    e = x - 15 < -40 ? -40 : (x - 15 > 127 ? 127 : x - 15);
  }
  r.scale = ldexpf(1.0f, e);
  for (int i = 0; i < 12; ++i) {
    const bool lower = (i % 2) == 0;
    // The change rounded outward in float first (so it never passes the exact change), then
    // scaled by 2^-e (exact but for values far below the lerp pad's floor) and rounded outward.
    const float change = lower ? rounding::sub<rounding::Round::Down>(b[i], a[i])
                               : rounding::sub<rounding::Round::Up>(b[i], a[i]);
    r.delta[i] = halfDirected(ldexpf(change, -e), lower);
  }
  return r;
}

}  // namespace tsah::motion
