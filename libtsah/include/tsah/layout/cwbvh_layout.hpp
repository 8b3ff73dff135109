#pragma once
// The traversal of the compressed 8-wide BVH (cwbvh_node.hpp: the node; cwbvh_quantize.hpp: its
// quantization, both included here), shared by the CPU reference traversal and the CUDA kernels
// (TSAH_HD): the paper's stack-based traversal with node and triangle groups, the ray-local box
// test with directed rounding and the triangle test of woop.hpp.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/cwbvh_node.hpp"
#include "tsah/layout/cwbvh_quantize.hpp"
#include "tsah/core/directed_rounding.hpp"
#include "tsah/layout/gpu_layout.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah {

// End (exclusive offset) of the leaf starting at `offset` in a node whose leaves start at the
// offsets in `starts` (bit i set: a leaf begins at triBase + i).
TSAH_HD uint32_t cwbvhLeafEnd(uint64_t starts, uint32_t offset, uint32_t triCount) {
  const uint64_t above = offset >= 63 ? 0ull : starts & (~0ull << (offset + 1));
  if (above == 0) return triCount;
#if defined(__CUDA_ARCH__)
  return uint32_t(__ffsll((long long)above) - 1);
#else
  return uint32_t(__builtin_ctzll(above));
#endif
}

TSAH_HD uint32_t cwbvhPopc(uint32_t x) {
#if defined(__CUDA_ARCH__)
  return uint32_t(__popc(x));
#else
  return uint32_t(__builtin_popcount(x));
#endif
}

TSAH_HD uint32_t cwbvhLowestBit(uint64_t x) {
#if defined(__CUDA_ARCH__)
  return uint32_t(__ffsll((long long)x) - 1);
#else
  return uint32_t(__builtin_ctzll(x));
#endif
}

// Everything the traversal reads for one frame (pointers only; pass by value).
struct CwbvhView {
  const CwbvhNode* nodes = nullptr;
  const WoopTriangle* woop = nullptr;   // per slot of the compressed layout
  const uint32_t* triIndex = nullptr;   // slot -> triangle id
  const uint32_t* indices = nullptr;    // 3 per triangle id
  const float* positions = nullptr;     // xyz per vertex, this frame
  int32_t rootRef = 0;                  // node 0, or a leaf reference when the tree is one leaf
  uint32_t rootCount = 0;
  Aabb rootBox;
};

// The node as the traversal reads it: 20 words, with every field taken out by a constant byte
// offset, so that on the GPU (slot loop unrolled) the node lives in registers.
struct CwbvhNodeWords {
  uint32_t w[20];

  TSAH_HD uint32_t byteAt(uint32_t offset) const { return (w[offset >> 2] >> (8u * (offset & 3u))) & 0xffu; }
  TSAH_HD float floatAt(uint32_t word) const {
#if defined(__CUDA_ARCH__)
    return __uint_as_float(w[word]);
#else
    float f;
    std::memcpy(&f, &w[word], sizeof f);
    return f;
#endif
  }
  // Slot masks (bit s: slot s) of the interior and of the leaf children, from the meta words.
  TSAH_HD uint32_t interiorSlots() const { return slotFlags(w[6]) | (slotFlags(w[7]) << 4); }
  TSAH_HD uint32_t leafSlots() const {  // kCwbvhLeaf set and kCwbvhInterior clear
    return slotFlags((w[6] << 1) & ~w[6]) | (slotFlags((w[7] << 1) & ~w[7]) << 4);
  }
  // Bit 7 of each byte of x, as bits 0-3 (the four products land on distinct bits: no carries).
  TSAH_HD static uint32_t slotFlags(uint32_t x) { return ((x & 0x80808080u) * 0x00204081u) >> 28; }
  // The meta byte of a slot known only at run time: selects between the two words instead of
  // indexing the node's registers (which would move the node to local memory on the GPU).
  TSAH_HD uint32_t metaOf(uint32_t slot) const { return ((slot < 4 ? w[6] : w[7]) >> (8u * (slot & 3u))) & 0xffu; }
  // The end (offset from triBase, exclusive) of the leaf in `slot`, leafSlots being this node's
  // leafSlots(): where the node's next leaf begins (leaves are stored in slot order), or triCount.
  TSAH_HD uint32_t leafEnd(uint32_t slot, uint32_t leafSlots) const {
    const uint32_t later = leafSlots & ~((2u << slot) - 1u);
    return later != 0 ? metaOf(cwbvhLowestBit(later)) & 0x3fu : byteAt(15);
  }
};
static_assert(offsetof(CwbvhNode, ex) == 12 && offsetof(CwbvhNode, triCount) == 15 &&
              offsetof(CwbvhNode, childBase) == 16 && offsetof(CwbvhNode, triBase) == 20 &&
              offsetof(CwbvhNode, meta) == 24 && offsetof(CwbvhNode, qlo) == 32 && offsetof(CwbvhNode, qhi) == 56);

// One bound per axis of the eight children, as the words of the node that hold it: the near planes
// of a ray with direction signs `oct` (bit a set: dir[a] < 0, the near plane is hi) or, with
// oct ^ 7, the far planes.
inline constexpr float kCwbvhGridBias = 8388608.0f;  // 2^23

struct CwbvhPlaneWords {
  uint32_t w[6];  // axis a: words 2a, 2a + 1 (slots 0-3, 4-7)
  // The bound q of `slot` along `axis` as the float 2^23 + q (exact: bits 0x4B0000qq). On the GPU
  // that is one byte permute: no integer-to-float conversion and no shift/mask pair, which kept
  // the integer pipe the traversal's bottleneck. CwbvhSlabLine takes the 2^23 out of its offset.
  TSAH_HD float biasedAt(uint32_t axis, uint32_t slot) const {
    const uint32_t word = w[2 * axis + (slot >> 2)];
#if defined(__CUDA_ARCH__)
    return __uint_as_float(__byte_perm(word, 0x4B000000u, 0x7440u | (slot & 3u)));
#else
    return float((word >> (8u * (slot & 3u))) & 0xffu) + kCwbvhGridBias;
#endif
  }
};

TSAH_HD CwbvhPlaneWords cwbvhNearPlanes(const CwbvhNodeWords& n, uint32_t oct) {
  CwbvhPlaneWords planes;
  TSAH_CWBVH_UNROLL
  for (uint32_t a = 0; a < 3; ++a) {
    const uint32_t lo = 8 + 2 * a, hi = 14 + 2 * a;  // words of qlo[a] and qhi[a]
    const bool negative = (oct >> a) & 1u;
    planes.w[2 * a] = negative ? n.w[hi] : n.w[lo];
    planes.w[2 * a + 1] = negative ? n.w[hi + 1] : n.w[lo + 1];
  }
  return planes;
}

// How a traversal loads a node: plain loads on the CPU, read-only cache on the GPU.
TSAH_HD CwbvhNodeWords cwbvhLoadNode(const CwbvhNode* nodes, uint32_t i) {
  CwbvhNodeWords n;
#if defined(__CUDA_ARCH__)
  const uint4* src = reinterpret_cast<const uint4*>(nodes + i);
#pragma unroll
  for (int k = 0; k < 5; ++k) {
    const uint4 v = __ldg(src + k);
    n.w[4 * k] = v.x;
    n.w[4 * k + 1] = v.y;
    n.w[4 * k + 2] = v.z;
    n.w[4 * k + 3] = v.w;
  }
#else
  std::memcpy(n.w, nodes + i, sizeof n.w);
#endif
  return n;
}

TSAH_HD WoopTriangle cwbvhLoadWoop(const WoopTriangle* woop, uint32_t s) {
#if defined(__CUDA_ARCH__)
  const float4* p = reinterpret_cast<const float4*>(woop + s);
  const float4 a = __ldg(p), b = __ldg(p + 1), c = __ldg(p + 2);
  return {{a.x, a.y, a.z, a.w}, {b.x, b.y, b.z, b.w}, {c.x, c.y, c.z, c.w}};
#else
  return woop[s];
#endif
}

TSAH_HD uint32_t cwbvhLoadU32(const uint32_t* p) {
#if defined(__CUDA_ARCH__)
  return __ldg(p);
#else
  return *p;
#endif
}

// Moves bit s of an 8-bit slot mask to bit s ^ oct.
TSAH_HD uint32_t cwbvhPermuteSlots(uint32_t m, uint32_t oct) {
  if (oct & 1u) m = ((m & 0x55u) << 1) | ((m >> 1) & 0x55u);
  if (oct & 2u) m = ((m & 0x33u) << 2) | ((m >> 2) & 0x33u);
  if (oct & 4u) m = ((m & 0x0fu) << 4) | ((m >> 4) & 0x0fu);
  return m;
}

// The ray's slab distance to a node's planes along one axis, as a function of the 8-bit grid
// coordinate q: t(q) = q * c + b with c = step * invDir and b = (p - org) * invDir, evaluated as
// one FMA per plane on the biased coordinate g = 2^23 + q (CwbvhPlaneWords::biasedAt):
// t = g * c + (b - 2^23 * c). The near form bounds t from below and the far form from above, by
// directed rounding of c, of both offsets and of the FMA, so the slab interval computed contains
// the real one for the real planes p + q * step (which contain the exact box). Folding 2^23 into
// the offset rounds it at the scale of 2^23 * c, which widens each slab by at most about one grid
// step (conservative; it saves one subtraction per plane). A NaN (0 * inf, inf - inf from extreme
// coordinates or a direction near zero) drops out of the min/max of the box test, which only
// widens the interval. Together with kSlabFarScale (the rounding of invDir, as in intersectBox)
// no ray misses a box that the binary traversal enters.
struct CwbvhSlabLine {
  float nearC, nearB, farC, farB;  // near: t >= g * nearC + nearB; far: t <= g * farC + farB

  TSAH_HD float nearAt(float g) const { return rounding::fmaDown(g, nearC, nearB); }
  TSAH_HD float farAt(float g) const { return rounding::fmaUp(g, farC, farB); }
};

TSAH_HD CwbvhSlabLine cwbvhSlabLine(float p, float step, float org, float invDir, uint32_t negative) {
  const float dLo = rounding::subDown(p, org), dHi = rounding::subUp(p, org);  // p - org
  CwbvhSlabLine l;
  l.nearC = rounding::mulDown(step, invDir);
  l.farC = rounding::mulUp(step, invDir);
  const float nearB = rounding::mulDown(negative ? dHi : dLo, invDir);  // invDir < 0 flips which end is lower
  const float farB = rounding::mulUp(negative ? dLo : dHi, invDir);
  l.nearB = rounding::fmaDown(-kCwbvhGridBias, l.nearC, nearB);
  l.farB = rounding::fmaUp(-kCwbvhGridBias, l.farC, farB);
  return l;
}

// A slot's entry and exit distance from its three slab distances per side: max(a, b, c, tmin) and
// min(a, b, c, tmax), NaN dropping out. The three slabs go through one three-way max / min of their
// bits as signed integers (on sm_90 one instruction, VIMNMX3, where the float form needs two float
// min/max: the GPU box test is bound by that pipe); the CPU reference takes the same path, so both
// visit the same nodes. Bits of non-negative floats order like the floats and those of negative
// ones the other way round, so the integer form equals the float one where the three distances are
// non-negative (and no NaN), and elsewhere returns a value at or below the float max (entry) or at
// or above the float min (exit): the slab interval only widens, as it does where a NaN drops out,
// and no ray misses a box that the float form enters (CwbvhTraversal.SlabBitsWidenTheFloatInterval;
// for a ray whose tmin or tmax is NaN that does not hold, but the triangle test never reports a
// hit for such a ray either).
TSAH_HD float cwbvhBitsMax3(float a, float b, float c) {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  return __int_as_float(__vimax3_s32(__float_as_int(a), __float_as_int(b), __float_as_int(c)));
#else
  const int32_t m = std::max(std::max(int32_t(floatBits(a)), int32_t(floatBits(b))),
                             int32_t(floatBits(c)));
  return bitsFloat(uint32_t(m));
#endif
}
TSAH_HD float cwbvhBitsMin3(float a, float b, float c) {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  return __int_as_float(__vimin3_s32(__float_as_int(a), __float_as_int(b), __float_as_int(c)));
#else
  const int32_t m = std::min(std::min(int32_t(floatBits(a)), int32_t(floatBits(b))),
                             int32_t(floatBits(c)));
  return bitsFloat(uint32_t(m));
#endif
}
TSAH_HD float cwbvhSlabEntry(float a, float b, float c, float tmin) {
  return rounding::maxNum(cwbvhBitsMax3(a, b, c), tmin);
}
TSAH_HD float cwbvhSlabExit(float a, float b, float c, float tmax) {
  return rounding::minNum(cwbvhBitsMin3(a, b, c), tmax);
}

// The box test of one node for one ray: the three slab lines and the near and far plane words of
// the ray's octant, made once per node; hits(slot) tests one child slot.
struct CwbvhBoxTest {
  CwbvhSlabLine x, y, z;
  CwbvhPlaneWords near, far;

  TSAH_HD CwbvhBoxTest(const CwbvhNodeWords& n, const RayPrep& prep, uint32_t oct)
      : x(cwbvhSlabLine(n.floatAt(0), cwbvhStep(n.byteAt(12)), prep.org.x, prep.invDir.x, oct & 1u)),
        y(cwbvhSlabLine(n.floatAt(1), cwbvhStep(n.byteAt(13)), prep.org.y, prep.invDir.y, oct & 2u)),
        z(cwbvhSlabLine(n.floatAt(2), cwbvhStep(n.byteAt(14)), prep.org.z, prep.invDir.z, oct & 4u)),
        // Near and far planes per axis by the ray's direction (octant): for dir >= 0 the near plane
        // is lo, else hi.
        near(cwbvhNearPlanes(n, oct)),
        far(cwbvhNearPlanes(n, oct ^ 7u)) {}

  // Whether the ray's interval [tmin, tmax] meets the quantized box of `slot` (an empty slot's
  // planes are garbage: the caller masks its bit out).
  TSAH_HD bool hits(uint32_t slot, float tmin, float tmax) const {
    const float tn = cwbvhSlabEntry(x.nearAt(near.biasedAt(0, slot)), y.nearAt(near.biasedAt(1, slot)),
                                    z.nearAt(near.biasedAt(2, slot)), tmin);
    const float tf = cwbvhSlabExit(x.farAt(far.biasedAt(0, slot)), y.farAt(far.biasedAt(1, slot)),
                                   z.farAt(far.biasedAt(2, slot)), tmax) *
                     kSlabFarScale;
    return tn <= tf;
  }
};

// A group of interior children still to visit (the paper's node group): the children's base
// index, their interior-slot mask and the hit children as bits of slot ^ oct.
struct CwbvhNodeGroup {
  uint32_t base;
  uint32_t bits;  // hits in bits 0..7 (by slot ^ oct), interior mask in bits 8..15 (by slot)
};

namespace detail {

// Tests triangle slot s; on a hit shortens tmax and records it (the slot; the caller maps it).
TSAH_HD bool cwbvhTriangle(const CwbvhView& v, const Ray& ray, const RayPrep& prep, uint32_t s, float& tmax,
                           Hit& hit) {
  auto fetch = [&](Vec3& v0, Vec3& v1, Vec3& v2) {
    const uint32_t* tri = v.indices + 3 * std::size_t(cwbvhLoadU32(v.triIndex + s));
    const uint32_t a = cwbvhLoadU32(tri), b = cwbvhLoadU32(tri + 1), c = cwbvhLoadU32(tri + 2);
    v0 = {v.positions[3 * a], v.positions[3 * a + 1], v.positions[3 * a + 2]};
    v1 = {v.positions[3 * b], v.positions[3 * b + 1], v.positions[3 * b + 2]};
    v2 = {v.positions[3 * c], v.positions[3 * c + 1], v.positions[3 * c + 2]};
  };
  float t, u, w;
  if (!intersectTriangle(ray, prep, cwbvhLoadWoop(v.woop, s), tmax, fetch, t, u, w)) return false;
  tmax = t;
  hit.t = t;
  hit.u = u;
  hit.v = w;
  hit.tri = s;
  return true;
}

}  // namespace detail

// The paper's stack-based traversal: a node's hit interior children become one node group
// (visited in octant order), its hit leaves one triangle group, tested at once. The box test is
// the ray-local one of CwbvhSlabLine (intersectBox for a root that is one leaf), the triangle test
// intersectTriangle (woop.hpp). Written as a state that advances one node per step(), so that a
// GPU kernel may interleave rays (a persistent thread takes a new ray when its ray finishes);
// cwbvhClosestHit / cwbvhAnyHit run it to the end.
template <bool AnyHit>
struct CwbvhTraversal {
  Ray ray;
  RayPrep prep;
  Hit hit;           // hit.tri: the triangle slot until result()
  float tmax;
  uint32_t oct;      // bit a: dir[a] < 0
  CwbvhNodeGroup group;
  int sp;  // entries in the caller's stack (kept apart from this state, which then stays in registers)

  // Sets up the ray; returns whether any node remains to visit (false: result() is final, as for a
  // tree that is one leaf).
  TSAH_HD bool start(const CwbvhView& v, const Ray& r) {
    ray = r;
    hit = Hit{};
    prep = prepareRay(r);
    tmax = r.tmax;
    sp = 0;
    group = {0u, 0u};
    if (isLeafRef(v.rootRef)) {  // a tree that is one leaf (or empty)
      float tEntry;
      if (v.rootCount == 0 || !intersectBox(prep, v.rootBox, r.tmin, tmax, tEntry)) return false;
      const uint32_t first = leafFirstSlot(v.rootRef);
      for (uint32_t s = first; s < first + v.rootCount; ++s)
        if (detail::cwbvhTriangle(v, r, prep, s, tmax, hit) && AnyHit) break;
      return false;
    }
    // A ray that misses the whole tree (most camera rays of a small character in a wide frame)
    // ends here, before the root node is fetched. rootBox contains every child box, and the box
    // test is monotone, so no ray that could hit a triangle is dropped.
    float tEntry;
    if (!intersectBox(prep, v.rootBox, r.tmin, tmax, tEntry)) return false;
    oct = (r.dir.x < 0.0f ? 1u : 0u) | (r.dir.y < 0.0f ? 2u : 0u) | (r.dir.z < 0.0f ? 4u : 0u);
    group = {0u, (1u << oct) | (1u << 8)};  // the root as a group of one: interior slot 0, key 0 ^ oct
    return true;
  }

  // Visits one node: its children's boxes, the triangles of its hit leaves. Returns whether nodes
  // remain (false: finished, or an any-hit ray found its hit).
  TSAH_HD bool step(const CwbvhView& v, CwbvhNodeGroup* stack) {
    if ((group.bits & 0xffu) == 0) {
      if (sp == 0) return false;
      group = stack[--sp];
    }
    const uint32_t key = cwbvhLowestBit(group.bits & 0xffu);
    group.bits &= ~(1u << key);
    const uint32_t slot = key ^ oct;
    const uint32_t imask = group.bits >> 8;
    const uint32_t nodeIndex = group.base + cwbvhPopc(imask & ((1u << slot) - 1u));
    const CwbvhNodeWords n = cwbvhLoadNode(v.nodes, nodeIndex);
    // Every slot's box is tested, empty ones too (their hit bit is masked out below): the slot loop
    // then carries no per-child meta decoding, which kept the integer pipe busy. The child kinds
    // come from the meta words as masks, once per node.
    const CwbvhBoxTest test(n, prep, oct);
    uint32_t boxHits = 0;
    TSAH_CWBVH_UNROLL
    for (uint32_t s = 0; s < kCwbvhWidth; ++s)
      if (test.hits(s, ray.tmin, tmax)) boxHits |= 1u << s;
    const uint32_t childInterior = n.interiorSlots(), leafSlots = n.leafSlots();
    uint32_t hitLeafSlots = boxHits & leafSlots;
    // Hit interior children by slot ^ oct (the visiting order).
    const uint32_t childHits = cwbvhPermuteSlots(boxHits & childInterior, oct);
    // The triangle group: every triangle of the hit leaves, in slot (= storage) order. A leaf ends
    // where the node's next leaf begins, or at triCount.
    while (hitLeafSlots != 0) {
      const uint32_t leafSlot = cwbvhLowestBit(hitLeafSlots);
      hitLeafSlots &= hitLeafSlots - 1;
      const uint32_t first = n.metaOf(leafSlot) & 0x3fu, end = n.leafEnd(leafSlot, leafSlots);
      for (uint32_t o = first; o < end; ++o) {
        if (detail::cwbvhTriangle(v, ray, prep, n.w[5] + o, tmax, hit) && AnyHit) {
          group.bits = 0;  // any hit: done
          sp = 0;
          return false;
        }
      }
    }
    if (childHits != 0) {
      if ((group.bits & 0xffu) != 0) stack[sp++] = group;
      group = {n.w[4], childHits | (childInterior << 8)};
    }
    return (group.bits & 0xffu) != 0 || sp != 0;
  }

  // The hit with the triangle id (of the animation) in place of the slot.
  TSAH_HD Hit result(const CwbvhView& v) const {
    Hit h = hit;
    if (h.valid()) h.tri = cwbvhLoadU32(v.triIndex + h.tri);
    return h;
  }
};

template <bool AnyHit, int StackSize>
TSAH_HD Hit cwbvhTraverse(const CwbvhView& v, const Ray& ray) {
  CwbvhTraversal<AnyHit> t;
  CwbvhNodeGroup stack[StackSize];
  if (t.start(v, ray))
    while (t.step(v, stack)) {
    }
  return t.result(v);
}

// Stack entries: one per wide level at most (a node pushes its remaining group once), so the
// binary tree's depth limit (kTraversalStackSize = 128) bounds it as well.
inline constexpr int kCwbvhStackSize = 128;

TSAH_HD Hit cwbvhClosestHit(const CwbvhView& v, const Ray& ray) {
  return cwbvhTraverse<false, kCwbvhStackSize>(v, ray);
}
TSAH_HD bool cwbvhAnyHit(const CwbvhView& v, const Ray& ray) {
  return cwbvhTraverse<true, kCwbvhStackSize>(v, ray).valid();
}

}  // namespace tsah
