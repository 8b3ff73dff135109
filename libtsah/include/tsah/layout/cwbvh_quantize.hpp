#pragma once
// The conservative quantization of a compressed 8-wide node's child boxes (cwbvh_node.hpp): the
// grid exponents, each slot's 8-bit planes and the union of the children, shared by the host
// (buildCwbvh, refitCwbvh, convertToCwbvh) and the GPU refit (TSAH_HD).
#include <cstdint>
#include <cstring>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/cwbvh_node.hpp"
#include "tsah/core/directed_rounding.hpp"
#include "tsah/core/float_bits.hpp"
#include "tsah/core/hd.hpp"

namespace tsah {

namespace detail {

// Whether 255 steps of exponent e from p reach hi in float (the real p + 255 step >= hi); always
// true for the largest exponent, 254.
TSAH_HD bool cwbvhExponentReaches(float p, float hi, uint32_t e) {
  return e >= 254 || rounding::addDown(p, 255.0f * cwbvhStep(e)) >= hi;
}

// The smallest exponent from an estimate upwards whose 255 steps from p reach hi. The estimate
// (the exponent of (hi - p) / 255) is one below the answer unless that quotient is a power of two,
// so the first two candidates are tested side by side (independent instruction chains, no loop);
// only when both fail does the search go on.
TSAH_HD uint32_t cwbvhExponent(float p, float hi) {
  const float d = (hi - p) * (1.0f / 255.0f);
  uint32_t e = (floatBits(d) >> 23) & 0xffu;  // d >= 0: 2^(e-127) <= d < 2^(e-126)
  if (!(d > 0.0f)) e = 1;                     // 0, or NaN
  if (e < 1) e = 1;
  if (e > 254) e = 254;
  const bool first = cwbvhExponentReaches(p, hi, e), second = cwbvhExponentReaches(p, hi, e + 1);
  if (first) return e;
  if (second) return e + 1;
  e += 2;
  while (!cwbvhExponentReaches(p, hi, e)) ++e;
  return e;
}

// floor / ceil of (x - p) / step clamped to 0..255, then moved until the decoded plane is on the
// conservative side (and as tight as it can be).
TSAH_HD uint32_t cwbvhGuess(float x, float p, uint32_t e) {
  const float f = (x - p) * cwbvhStep(254 - e);  // 1 / step = 2^(127 - e) = step of 254 - e
  if (!(f > 0.0f)) return 0;
  if (!(f < 255.0f)) return 255;
  return uint32_t(f);
}

// Whether the guess of x is within one of the answer: (x - p) rounded to nearest is within half an
// ulp of the real difference, so (x - p) / step is off by less than 256 * 2^-24, far below one,
// unless the difference is not finite (an overflow, an infinite or NaN coordinate) or 1 / step is
// not a normal float (e = 254).
TSAH_HD bool cwbvhGuessWithinOne(float x, float p, uint32_t e) {
  const float d = x - p;
  return e < 254 && d >= -3.402823466e38f && d <= 3.402823466e38f;
}

// Whether the real plane p + q * step lies at or below x / at or above x (decided exactly: the sum
// rounded up is <= x exactly when the real sum is, x being a float).
TSAH_HD bool cwbvhPlaneAtMost(float p, uint32_t q, float step, float x) {
  return rounding::addUp(p, float(q) * step) <= x;
}
TSAH_HD bool cwbvhPlaneAtLeast(float p, uint32_t q, float step, float x) {
  return rounding::addDown(p, float(q) * step) >= x;
}

// The searches by single steps (the reference, and the fallback when the guess may be further off).
TSAH_HD uint32_t cwbvhSearchLo(float lo, float p, float step, uint32_t q) {
  while (q > 0 && !cwbvhPlaneAtMost(p, q, step, lo)) --q;
  while (q < 255 && cwbvhPlaneAtMost(p, q + 1, step, lo)) ++q;
  return q;
}
TSAH_HD uint32_t cwbvhSearchHi(float hi, float p, float step, uint32_t q) {
  while (q < 255 && !cwbvhPlaneAtLeast(p, q, step, hi)) ++q;
  while (q > 0 && cwbvhPlaneAtLeast(p, q - 1, step, hi)) --q;
  return q;
}

// The largest q whose real plane is at or below lo (q = 0 always is: p is the node's lower corner).
// The planes are monotone in q, so the answer is unique: from a guess within one of it, the two
// neighbouring tests (side by side, no loop) settle it; otherwise the search does.
TSAH_HD uint32_t cwbvhQuantizeLo(float lo, float p, uint32_t e) {
  const float step = cwbvhStep(e);
  const uint32_t q = cwbvhGuess(lo, p, e);
  if (!cwbvhGuessWithinOne(lo, p, e)) return cwbvhSearchLo(lo, p, step, q);
  const bool atQ = q == 0 || cwbvhPlaneAtMost(p, q, step, lo);
  const bool atNext = q < 255 && cwbvhPlaneAtMost(p, q + 1, step, lo);
  return !atQ ? q - 1 : atNext ? q + 1 : q;
}

// The smallest q whose real plane is at or above hi (q = 255 always is, by the exponent's choice).
TSAH_HD uint32_t cwbvhQuantizeHi(float hi, float p, uint32_t e) {
  const float step = cwbvhStep(e);
  const uint32_t q = cwbvhGuess(hi, p, e);
  if (!cwbvhGuessWithinOne(hi, p, e)) return cwbvhSearchHi(hi, p, step, q);
  const bool atQ = q == 255 || cwbvhPlaneAtLeast(p, q, step, hi);
  const bool atPrevious = q > 0 && cwbvhPlaneAtLeast(p, q - 1, step, hi);
  return !atQ ? q + 1 : atPrevious ? q - 1 : q;
}

}  // namespace detail

// Whether slot's quantized box, with real (unrounded) planes p + q * step, contains box: what the
// quantizer guarantees and the traversal's box test relies on.
TSAH_HD bool cwbvhChildBoxContains(const CwbvhNode& n, uint32_t slot, const Aabb& box) {
  const float p[3] = {n.px, n.py, n.pz};
  const uint32_t e[3] = {n.ex, n.ey, n.ez};
  for (int a = 0; a < 3; ++a) {
    const float step = cwbvhStep(e[a]);
    if (!detail::cwbvhPlaneAtMost(p[a], n.qlo[a][slot], step, box.lo[a]) ||
        !detail::cwbvhPlaneAtLeast(p[a], n.qhi[a][slot], step, box.hi[a]))
      return false;
  }
  return true;
}

// Sets p, e, qlo and qhi of node n from the exact boxes of its occupied slots (boxes[slot], read
// only where meta[slot] != 0). Returns the union of those boxes (the node's exact box).
// Conservative: cwbvhChildBoxContains(n, s, boxes[s]) for every occupied slot, for any finite
// boxes (a plane beyond the float range is +-inf, which still contains it).
// The two steps of cwbvhQuantize, shared with the GPU refit (which runs the second one in a lane
// per slot): the node's grid exponents from the union of its children, and one slot's planes.
TSAH_HD void cwbvhGridExponents(const Aabb& all, uint32_t e[3]) {
  e[0] = detail::cwbvhExponent(all.lo.x, all.hi.x);
  e[1] = detail::cwbvhExponent(all.lo.y, all.hi.y);
  e[2] = detail::cwbvhExponent(all.lo.z, all.hi.z);
}

struct CwbvhSlotPlanes {
  uint8_t lo[3], hi[3];  // qlo, qhi per axis
};
// box: the exact box of an occupied slot; an empty slot gets the empty planes 255 / 0 (never read:
// meta says empty).
TSAH_HD CwbvhSlotPlanes cwbvhSlotPlanes(bool empty, const Aabb& box, const Aabb& all, const uint32_t e[3]) {
  CwbvhSlotPlanes q;
  TSAH_CWBVH_UNROLL
  for (int a = 0; a < 3; ++a) {
    q.lo[a] = empty ? uint8_t(255) : uint8_t(detail::cwbvhQuantizeLo(box.lo[a], all.lo[a], e[a]));
    q.hi[a] = empty ? uint8_t(0) : uint8_t(detail::cwbvhQuantizeHi(box.hi[a], all.lo[a], e[a]));
  }
  return q;
}

// The union of a node's occupied child boxes (occupied: bit s for slot s), formed in a fixed order
// of pairs: ((0 1) (2 3)) ((4 5) (6 7)), the lower half first, an empty half adding nothing. That
// is the order in which 8 lanes of a warp form it with three exchanges (the GPU refit), and the
// order fixes the bits where boxes tie at -0 / +0 or hold a NaN.
struct CwbvhPartialUnion {
  Aabb box;
  bool any = false;  // some occupied slot is in it
};
// c ? a : b, component by component (on the GPU a select of whole boxes, or early returns of
// them, went through local memory).
TSAH_HD Aabb cwbvhSelectBox(bool c, const Aabb& a, const Aabb& b) {
  Aabb r;
  r.lo = {c ? a.lo.x : b.lo.x, c ? a.lo.y : b.lo.y, c ? a.lo.z : b.lo.z};
  r.hi = {c ? a.hi.x : b.hi.x, c ? a.hi.y : b.hi.y, c ? a.hi.z : b.hi.z};
  return r;
}
// lower extended by upper; an empty half adds nothing.
TSAH_HD CwbvhPartialUnion cwbvhJoin(const CwbvhPartialUnion& lower, const CwbvhPartialUnion& upper) {
  Aabb joined = lower.box;
  joined.extend(upper.box);
  return {cwbvhSelectBox(lower.any && upper.any, joined, cwbvhSelectBox(lower.any, lower.box, upper.box)),
          lower.any || upper.any};
}
TSAH_HD Aabb cwbvhChildUnion(const Aabb* boxes, uint32_t occupied) {
  CwbvhPartialUnion part[kCwbvhWidth];
  TSAH_CWBVH_UNROLL
  for (uint32_t s = 0; s < kCwbvhWidth; ++s) {
    part[s].any = (occupied >> s) & 1u;
    if (part[s].any) part[s].box = boxes[s];
  }
  TSAH_CWBVH_UNROLL
  for (uint32_t width = 1; width < kCwbvhWidth; width *= 2)
    TSAH_CWBVH_UNROLL
    for (uint32_t s = 0; s < kCwbvhWidth; s += 2 * width) part[s] = cwbvhJoin(part[s], part[s + width]);
  return part[0].box;
}

TSAH_HD Aabb cwbvhQuantize(CwbvhNode& n, const Aabb* boxes) {
  uint32_t occupied = 0;
  for (uint32_t s = 0; s < kCwbvhWidth; ++s) occupied |= n.isEmpty(s) ? 0u : 1u << s;
  const Aabb all = cwbvhChildUnion(boxes, occupied);
  n.px = all.lo.x;
  n.py = all.lo.y;
  n.pz = all.lo.z;
  uint32_t e[3];
  cwbvhGridExponents(all, e);
  n.ex = uint8_t(e[0]);
  n.ey = uint8_t(e[1]);
  n.ez = uint8_t(e[2]);
  TSAH_CWBVH_UNROLL
  for (uint32_t s = 0; s < kCwbvhWidth; ++s) {
    const CwbvhSlotPlanes q = cwbvhSlotPlanes(n.isEmpty(s), n.isEmpty(s) ? all : boxes[s], all, e);
    for (int a = 0; a < 3; ++a) {
      n.qlo[a][s] = q.lo[a];
      n.qhi[a][s] = q.hi[a];
    }
  }
  return all;
}

}  // namespace tsah
