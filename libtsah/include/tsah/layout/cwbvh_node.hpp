#pragma once
// The compressed 8-wide BVH node (Ylitie, Karras, Laine, "Efficient Incoherent Ray Traversal on
// GPUs Through Compressed Wide BVHs", HPG 2017) and the decoding of its child boxes, shared by the
// CPU (reference, tests) and the CUDA runtime (TSAH_HD: one copy of the arithmetic). Its
// quantization is cwbvh_quantize.hpp, the traversal cwbvh_layout.hpp (which includes both);
// docs/cwbvh.md describes the layout; cwbvh_build.hpp builds it from a WideBvh.
//
// One node is 80 bytes (five 16-byte loads):
//   p[3]         float origin of the node's local grid (the lower corner of the union of its children)
//   e[3]         biased power-of-two exponents: the grid step along axis a is 2^(e[a] - 127)
//   triCount     triangles of the node's leaf children, slots [triBase, triBase + triCount) (<= 64)
//   childBase    interior children are nodes childBase + rank, rank = interior children in lower slots
//   triBase      first triangle slot of the node's leaf children
//   meta[8]      per child slot: 0 empty, kCwbvhInterior, or kCwbvhLeaf | offset (the leaf's first
//                triangle is triBase + offset; it ends where the next leaf of the node begins, or at
//                triCount: leaves are stored in slot order)
//   qlo/qhi      8-bit child box bounds per axis: lo = p + qlo * step, hi = p + qhi * step (float)
// Quantization is conservative in real arithmetic: every plane p + q * step, as a real number,
// lies on the outer side of the exact float box (so the rounded decode does too), and the traversal
// bounds its slab distances with directed rounding (below), so no ray misses a triangle that the
// binary tree's traversal hits.
//
// Children are placed in slots by direction (the paper's octant order): bit a of the slot is 1
// for a child on the + side of the node along axis a. A ray whose direction has sign bits `oct`
// (bit a set when dir[a] < 0) visits the hit children in increasing order of slot ^ oct, i.e.
// roughly near to far.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"

// Unrolls the loops over a node's eight slots on the GPU (the node then stays in registers).
#if defined(__CUDA_ARCH__)
#define TSAH_CWBVH_UNROLL _Pragma("unroll")
#else
#define TSAH_CWBVH_UNROLL
#endif

namespace tsah {

inline constexpr uint32_t kCwbvhWidth = 8;
inline constexpr uint32_t kCwbvhMaxNodeTriangles = 64;  // bits of the triangle mask
inline constexpr uint8_t kCwbvhInterior = 0x80;
inline constexpr uint8_t kCwbvhLeaf = 0x40;  // | offset (0..63)

struct alignas(16) CwbvhNode {
  float px, py, pz;
  uint8_t ex, ey, ez;
  uint8_t triCount;
  uint32_t childBase;
  uint32_t triBase;
  uint8_t meta[8];
  uint8_t qlo[3][8];  // [axis][slot]
  uint8_t qhi[3][8];

  TSAH_HD bool isEmpty(uint32_t slot) const { return meta[slot] == 0; }
  TSAH_HD bool isInterior(uint32_t slot) const { return (meta[slot] & kCwbvhInterior) != 0; }
  TSAH_HD bool isLeaf(uint32_t slot) const { return (meta[slot] & 0xc0) == kCwbvhLeaf; }
  TSAH_HD uint32_t leafOffset(uint32_t slot) const { return meta[slot] & 0x3fu; }
};

static_assert(sizeof(CwbvhNode) == 80 && alignof(CwbvhNode) == 16);
static_assert(std::is_trivially_copyable_v<CwbvhNode> && std::is_standard_layout_v<CwbvhNode>);

// 2^(e - 127) for a biased exponent 1..254 (a normal float power of two).
TSAH_HD float cwbvhStep(uint32_t e) {
#if defined(__CUDA_ARCH__)
  return __int_as_float(int(e << 23));
#else
  const uint32_t bits = e << 23;
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
#endif
}

// The decoded plane rounded to nearest (q * step is exact: 8-bit q times a power of two, so the
// fused form rounds once, like p + q * step). For tests and the host's view of a child box; the
// quantizer and the traversal work with the real value p + q * step instead (directed rounding).
TSAH_HD float cwbvhDecode(float p, float q, float step) {
#if defined(__CUDA_ARCH__)
  return __fmaf_rn(q, step, p);
#else
  return p + q * step;
#endif
}

TSAH_HD Aabb cwbvhChildBox(const CwbvhNode& n, uint32_t slot) {
  const float sx = cwbvhStep(n.ex), sy = cwbvhStep(n.ey), sz = cwbvhStep(n.ez);
  Aabb b;
  b.lo = {cwbvhDecode(n.px, n.qlo[0][slot], sx), cwbvhDecode(n.py, n.qlo[1][slot], sy),
          cwbvhDecode(n.pz, n.qlo[2][slot], sz)};
  b.hi = {cwbvhDecode(n.px, n.qhi[0][slot], sx), cwbvhDecode(n.py, n.qhi[1][slot], sy),
          cwbvhDecode(n.pz, n.qhi[2][slot], sz)};
  return b;
}

}  // namespace tsah
