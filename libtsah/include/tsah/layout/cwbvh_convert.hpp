#pragma once
// The compressed 8-wide layout (cwbvh_layout.hpp) of a binary tree in the GpuBvhNode form, made
// top-down one wide node at a time: the per-node steps, shared (TSAH_HD) by the host emulation
// (convertToCwbvh below, the tests' reference) and the GPU conversion of the per-frame rebuilds
// (cuda_kernels/src/cwbvh_rebuild.cu), and the child -> slot assignment shared with buildCwbvh.
//
// A wide node starts at one binary node and opens its interior children greedily, the largest
// surface area first, until it has 8 children (the standard greedy wide collapse). A binary leaf,
// or a binary subtree of at most `mergeLimit` triangles in one contiguous slot range, becomes one
// leaf child. Children go into slots by direction (cwbvhAssignSlots, as buildCwbvh does).
//
// Level by level (wide level L: the wide nodes [begin, end)), the nodes of a level are numbered in
// order; node i's interior children get the consecutive indices childBase + rank after the level,
// its leaf triangles the consecutive new slots triBase + offset, both exclusive prefix sums over
// the level's nodes of (interior children, leaf triangles). So the result is breadth-first, a
// node's leaf triangles are contiguous and in slot order, and it does not depend on how many
// threads do the work: the GPU's bytes equal the host's.
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/layout/cwbvh_layout.hpp"
#include "tsah/layout/gpu_layout.hpp"
#include "tsah/core/hd.hpp"

namespace tsah {

// A leaf child holds at most 8 triangles, so a node's leaves hold at most 64 (the triangle mask).
inline constexpr uint32_t kCwbvhMaxLeafTriangles = kCwbvhMaxNodeTriangles / kCwbvhWidth;
// Binary subtrees of at most this many triangles can become one leaf child (the paper's leaves:
// <= 3); off by default: the rebuilds' own SAH collapse already chose the leaves, and on an H100
// (Kitchen, LBVH) merging up to 3 traced no faster (2,200 vs 2,214 MRays/s) and converted slower.
inline constexpr uint32_t kCwbvhDefaultMergeTriangles = 0;

// The loops below run over all 8 slots with constant indices (unrolled on the GPU), so a thread's
// children, scores and slots stay in registers: dynamic indexing would put them in local memory,
// which made the first version of the GPU conversion latency-bound (~30-60 us per wide level).

// Adds one frame's vote for the direction of each child: the offset of its box centre from the
// centre of the children's union, relative to the union's extent per axis (0 on a flat axis).
// One child's vote, added to `offset`: box's centre relative to the union's centre and extent.
TSAH_HD void cwbvhAddCentreOffset(const Aabb& box, const Vec3& centre, const Vec3& ext, Vec3& offset) {
  const Vec3 d = box.center() - centre;
  TSAH_CWBVH_UNROLL
  for (int a = 0; a < 3; ++a) offset[a] += ext[a] > 0.0f ? d[a] / ext[a] : 0.0f;
}

TSAH_HD void cwbvhAddCentreOffsets(const Aabb* boxes, uint32_t n, Vec3* offset) {
  Aabb all;
  TSAH_CWBVH_UNROLL
  for (uint32_t c = 0; c < kCwbvhWidth; ++c)
    if (c < n) all.extend(boxes[c]);
  const Vec3 centre = all.center();
  const Vec3 ext = all.extent();
  TSAH_CWBVH_UNROLL
  for (uint32_t c = 0; c < kCwbvhWidth; ++c)
    if (c < n) cwbvhAddCentreOffset(boxes[c], centre, ext, offset[c]);
}

// A float's order as an unsigned integer (-0 taken as +0, which compares equal to it).
TSAH_HD uint32_t cwbvhOrderedBits(float f) {
  if (f == 0.0f) f = 0.0f;
  const uint32_t u = floatBits(f);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

TSAH_HD uint64_t cwbvhMax64(uint64_t a, uint64_t b) { return a > b ? a : b; }

// How far a child whose offset is o points into slot s's octant (bit a of s: + side of axis a),
// as an ordered integer.
TSAH_HD uint32_t cwbvhSlotScore(const Vec3& o, uint32_t s) {
  return cwbvhOrderedBits(((s & 1u) ? o.x : -o.x) + ((s & 2u) ? o.y : -o.y) + ((s & 4u) ? o.z : -o.z));
}
// The key of the pair (child c, slot s) with that score: larger wins; ties go to the lowest child,
// then the lowest slot. cwbvhKeyPair gives back 8 * c + s.
TSAH_HD uint64_t cwbvhSlotKey(uint32_t score, uint32_t c, uint32_t s) {
  return (uint64_t(score) << 32) | (63u - (8u * c + s));
}
TSAH_HD uint32_t cwbvhKeyPair(uint64_t key) { return 63u - uint32_t(key & 63u); }

// Child -> slot (slotOf[c] for c < n <= 8): greedily over all (child, free slot) pairs, the child
// whose offset points farthest into a slot's octant (bit a of the slot: + side of axis a) gets it
// (the paper's assignment). Ties: the lowest child, then the lowest slot. Each round takes the
// largest key (score's order, then 63 - (8 * child + slot)) of the free pairs as a tree of maxima
// instead of a chain of 64 dependent comparisons (a GPU thread's latency per wide node).
TSAH_HD void cwbvhAssignSlots(const Vec3* offset, uint32_t n, uint32_t* slotOf) {
  uint32_t order[kCwbvhWidth][kCwbvhWidth];
  TSAH_CWBVH_UNROLL
  for (uint32_t c = 0; c < kCwbvhWidth; ++c) {
    const Vec3 o = c < n ? offset[c] : Vec3{0.0f, 0.0f, 0.0f};
    TSAH_CWBVH_UNROLL
    for (uint32_t s = 0; s < kCwbvhWidth; ++s) order[c][s] = cwbvhSlotScore(o, s);
  }
  uint32_t usedSlots = 0, assigned = 0;
  for (uint32_t round = 0; round < n; ++round) {
    uint64_t rowBest[kCwbvhWidth];
    TSAH_CWBVH_UNROLL
    for (uint32_t c = 0; c < kCwbvhWidth; ++c) {
      uint64_t key[kCwbvhWidth];  // 0 for a pair that is not free (a free pair's key is larger)
      TSAH_CWBVH_UNROLL
      for (uint32_t s = 0; s < kCwbvhWidth; ++s) {
        const bool free = c < n && !((assigned >> c) & 1u) && !((usedSlots >> s) & 1u);
        key[s] = free ? cwbvhSlotKey(order[c][s], c, s) : 0u;
      }
      rowBest[c] = cwbvhMax64(cwbvhMax64(cwbvhMax64(key[0], key[1]), cwbvhMax64(key[2], key[3])),
                              cwbvhMax64(cwbvhMax64(key[4], key[5]), cwbvhMax64(key[6], key[7])));
    }
    const uint64_t best =
        cwbvhMax64(cwbvhMax64(cwbvhMax64(rowBest[0], rowBest[1]), cwbvhMax64(rowBest[2], rowBest[3])),
                   cwbvhMax64(cwbvhMax64(rowBest[4], rowBest[5]), cwbvhMax64(rowBest[6], rowBest[7])));
    const uint32_t pair = cwbvhKeyPair(best);
    const uint32_t bestC = pair >> 3, bestS = pair & 7u;
    TSAH_CWBVH_UNROLL
    for (uint32_t c = 0; c < kCwbvhWidth; ++c)
      if (c == bestC) slotOf[c] = bestS;
    assigned |= 1u << bestC;
    usedSlots |= 1u << bestS;
  }
}

// The binary tree as the conversion reads it (GpuBvhNode form: a FlatBvh's frame block, or a GPU
// rebuild's node array, where unreferenced nodes are never read).
struct BinaryTreeView {
  const GpuBvhNode* nodes = nullptr;
  uint32_t nodeCount = 0;             // references must be below it
  const uint32_t* triIndex = nullptr;  // binary slot -> triangle id
  uint32_t triangles = 0;
};

// One child of a wide node: a binary interior node (ref >= 0, count 0) or a leaf (leaf reference
// to its first binary slot, count triangles).
struct CwbvhOpenChild {
  int32_t ref;
  uint32_t count;
  Aabb box;
};

// The children of one wide node by slot (occupied: bit s set when slot s has a child).
struct CwbvhOpening {
  uint32_t occupied = 0;
  CwbvhOpenChild slot[kCwbvhWidth];
  uint32_t interior = 0;   // interior children
  uint32_t triangles = 0;  // triangles of the leaf children (<= 64)
};

namespace detail {

TSAH_HD GpuBvhNode cwbvhLoadBinaryNode(const GpuBvhNode* nodes, uint32_t i) {
#if defined(__CUDA_ARCH__)
  const float4* p = reinterpret_cast<const float4*>(nodes + i);
  const float4 a = __ldg(p), b = __ldg(p + 1), c = __ldg(p + 2), d = __ldg(p + 3);
  GpuBvhNode n;
  n.c0loX = a.x, n.c0hiX = a.y, n.c0loY = a.z, n.c0hiY = a.w;
  n.c1loX = b.x, n.c1hiX = b.y, n.c1loY = b.z, n.c1hiY = b.w;
  n.c0loZ = c.x, n.c0hiZ = c.y, n.c1loZ = c.z, n.c1hiZ = c.w;
  n.ref0 = __float_as_int(d.x), n.ref1 = __float_as_int(d.y);
  n.count0 = __float_as_uint(d.z), n.count1 = __float_as_uint(d.w);
  return n;
#else
  return nodes[i];
#endif
}

TSAH_HD bool cwbvhLeafInRange(const BinaryTreeView& t, int32_t ref, uint32_t count) {
  const uint32_t first = leafFirstSlot(ref);
  return count >= 1 && first < t.triangles && count <= t.triangles - first;
}

// The binary subtree `ref` (an interior node) as one slot range [first, first + count) when it
// holds at most `limit` (<= kCwbvhMaxLeafTriangles) triangles whose slots are contiguous. Every
// subtree still on the stack holds at least one triangle, so the walk stops after O(limit) nodes.
TSAH_HD bool cwbvhSmallSubtree(const BinaryTreeView& t, int32_t ref, uint32_t limit, uint32_t& first,
                               uint32_t& count) {
  if (limit > kCwbvhMaxLeafTriangles) limit = kCwbvhMaxLeafTriangles;  // the stack's size
  int32_t stackRef[kCwbvhMaxLeafTriangles + 1];
  uint32_t stackCount[kCwbvhMaxLeafTriangles + 1];
  uint32_t sp = 0, total = 0, lo = 0xffffffffu, hi = 0;
  stackRef[sp] = ref;
  stackCount[sp++] = 0;
  while (sp > 0) {
    --sp;
    const int32_t r = stackRef[sp];
    const uint32_t c = stackCount[sp];
    if (isLeafRef(r)) {
      if (!cwbvhLeafInRange(t, r, c)) return false;
      total += c;
      lo = leafFirstSlot(r) < lo ? leafFirstSlot(r) : lo;
      hi = leafFirstSlot(r) + c > hi ? leafFirstSlot(r) + c : hi;
      if (total > limit) return false;
      continue;
    }
    if (total + sp + 2 > limit || uint32_t(r) >= t.nodeCount) return false;
    const GpuBvhNode n = cwbvhLoadBinaryNode(t.nodes, uint32_t(r));
    stackRef[sp] = n.ref1;
    stackCount[sp++] = n.count1;
    stackRef[sp] = n.ref0;
    stackCount[sp++] = n.count0;
  }
  if (hi - lo != total) return false;  // not one contiguous range
  first = lo;
  count = total;
  return true;
}

// Child `side` of binary node n as a wide child: binary leaves and small subtrees become leaves.
TSAH_HD CwbvhOpenChild cwbvhBinaryChild(const BinaryTreeView& t, const GpuBvhNode& n, int side, uint32_t mergeLimit) {
  CwbvhOpenChild c{n.childRef(side), isLeafRef(n.childRef(side)) ? n.childCount(side) : 0u, n.childBox(side)};
  uint32_t first = 0, count = 0;
  if (!isLeafRef(c.ref) && mergeLimit >= 2 && cwbvhSmallSubtree(t, c.ref, mergeLimit, first, count)) {
    c.ref = makeLeafRef(first);
    c.count = count;
  }
#if defined(__CUDA_ARCH__)
  // An interior child may be opened next: start moving its node into L1 now, so that the
  // opening's chain of dependent node loads waits on L1 rather than L2.
  if (!isLeafRef(c.ref) && uint32_t(c.ref) < t.nodeCount)
    asm volatile("prefetch.global.L1 [%0];" ::"l"(t.nodes + c.ref));
#endif
  return c;
}

}  // namespace detail

// The children of the wide node that starts at binary reference `ref` (a leaf reference with
// `count` triangles and box `box` only for a tree that is one leaf) and their slots. mergeLimit
// must be <= kCwbvhMaxLeafTriangles. Returns false when the input is not a valid binary tree (a
// reference or leaf out of range, an empty leaf) or the leaf children hold more than 64
// triangles, which binary leaves of at most kCwbvhMaxLeafTriangles never do.
TSAH_HD bool cwbvhOpen(const BinaryTreeView& t, int32_t ref, uint32_t count, const Aabb& box, uint32_t mergeLimit,
                       CwbvhOpening& o) {
  CwbvhOpenChild child[kCwbvhWidth];  // in opening order
  float area[kCwbvhWidth];            // of the children (compared only for interior ones)
  TSAH_CWBVH_UNROLL
  for (uint32_t c = 0; c < kCwbvhWidth; ++c) area[c] = 0.0f;
  uint32_t n = 0;
  if (isLeafRef(ref)) {
    child[0] = {ref, count, box};
    n = 1;
  } else {
    if (uint32_t(ref) >= t.nodeCount) return false;
    const GpuBvhNode root = detail::cwbvhLoadBinaryNode(t.nodes, uint32_t(ref));
    child[0] = detail::cwbvhBinaryChild(t, root, 0, mergeLimit);
    child[1] = detail::cwbvhBinaryChild(t, root, 1, mergeLimit);
    area[0] = child[0].box.area();
    area[1] = child[1].box.area();
    n = 2;
    while (n < kCwbvhWidth) {
      int widest = -1;
      float widestArea = 0.0f;
      int32_t widestRef = 0;
      TSAH_CWBVH_UNROLL
      for (uint32_t c = 0; c < kCwbvhWidth; ++c) {
        if (c >= n || isLeafRef(child[c].ref)) continue;
        if (widest < 0 || area[c] > widestArea) {
          widest = int(c);
          widestArea = area[c];
          widestRef = child[c].ref;
        }
      }
      if (widest < 0) break;
      if (uint32_t(widestRef) >= t.nodeCount) return false;
      const GpuBvhNode node = detail::cwbvhLoadBinaryNode(t.nodes, uint32_t(widestRef));
      const CwbvhOpenChild first = detail::cwbvhBinaryChild(t, node, 0, mergeLimit);
      const CwbvhOpenChild second = detail::cwbvhBinaryChild(t, node, 1, mergeLimit);
      const float firstArea = first.box.area(), secondArea = second.box.area();
      TSAH_CWBVH_UNROLL
      for (uint32_t c = 0; c < kCwbvhWidth; ++c) {
        if (c == uint32_t(widest)) {
          child[c] = first;
          area[c] = firstArea;
        }
        if (c == n) {
          child[c] = second;
          area[c] = secondArea;
        }
      }
      ++n;
    }
  }
  o.interior = 0;
  o.triangles = 0;
  Aabb boxes[kCwbvhWidth];
  Vec3 offset[kCwbvhWidth];
  bool valid = true;
  TSAH_CWBVH_UNROLL
  for (uint32_t c = 0; c < kCwbvhWidth; ++c) {
    offset[c] = Vec3{0.0f, 0.0f, 0.0f};
    if (c >= n) continue;
    const CwbvhOpenChild& ch = child[c];
    if (!isLeafRef(ch.ref)) {
      valid = valid && uint32_t(ch.ref) < t.nodeCount;
      ++o.interior;
    } else {
      valid = valid && detail::cwbvhLeafInRange(t, ch.ref, ch.count);
      o.triangles += ch.count;
    }
    boxes[c] = ch.box;
  }
  if (!valid || o.triangles > kCwbvhMaxNodeTriangles) return false;
  cwbvhAddCentreOffsets(boxes, n, offset);
  uint32_t slotOf[kCwbvhWidth];
  cwbvhAssignSlots(offset, n, slotOf);
  // By slot.
  o.occupied = 0;
  TSAH_CWBVH_UNROLL
  for (uint32_t c = 0; c < kCwbvhWidth; ++c) {
    if (c >= n) continue;
    TSAH_CWBVH_UNROLL
    for (uint32_t s = 0; s < kCwbvhWidth; ++s)
      if (slotOf[c] == s) o.slot[s] = child[c];
    o.occupied |= 1u << slotOf[c];
  }
  return true;
}

// Where cwbvhWriteNode puts its results. exactBoxes and parentSlot may be null (the GPU needs
// neither; the host keeps them for validateCwbvh and refitCwbvh).
struct CwbvhConvertOutput {
  CwbvhNode* nodes = nullptr;
  int32_t* starts = nullptr;      // per wide node: the binary reference it starts at
  uint32_t* triIndex = nullptr;   // new slot -> triangle id
  Aabb* exactBoxes = nullptr;     // nodes * 8
  uint32_t* parentSlot = nullptr;  // per wide node: parent * 8 + slot
};

// The triangle ids of the binary leaf (ref, count) into dst[0, count).
TSAH_HD void cwbvhCopyLeafTriangles(const BinaryTreeView& t, int32_t ref, uint32_t count, uint32_t* dst) {
  const uint32_t first = leafFirstSlot(ref);
  if (count <= kCwbvhMaxLeafTriangles) {
    // All loads of the leaf first, then the stores: one memory latency per leaf instead of one per
    // triangle (a load-store loop waits on each load; on the GPU that was most of a level).
    uint32_t ids[kCwbvhMaxLeafTriangles];
    TSAH_CWBVH_UNROLL
    for (uint32_t k = 0; k < kCwbvhMaxLeafTriangles; ++k) ids[k] = k < count ? cwbvhLoadU32(t.triIndex + first + k) : 0u;
    TSAH_CWBVH_UNROLL
    for (uint32_t k = 0; k < kCwbvhMaxLeafTriangles; ++k)
      if (k < count) dst[k] = ids[k];
  } else {  // a one-leaf tree's root (up to 64 triangles)
    for (uint32_t k = 0; k < count; ++k) dst[k] = cwbvhLoadU32(t.triIndex + first + k);
  }
}

// Writes wide node `self` from its opening: interior children become nodes childBase + rank (and
// their start references), leaf triangles the slots triBase + offset in slot order; the child
// boxes are quantized with cwbvhQuantize.
TSAH_HD void cwbvhWriteNode(const BinaryTreeView& t, const CwbvhOpening& o, uint32_t self, uint32_t childBase,
                            uint32_t triBase, const CwbvhConvertOutput& out) {
  CwbvhNode n{};
  n.childBase = childBase;
  n.triBase = triBase;
  Aabb boxes[kCwbvhWidth];
  uint32_t rank = 0, offset = 0;
  TSAH_CWBVH_UNROLL
  for (uint32_t s = 0; s < kCwbvhWidth; ++s) {
    if (!((o.occupied >> s) & 1u)) continue;
    const CwbvhOpenChild& ch = o.slot[s];
    boxes[s] = ch.box;
    if (out.exactBoxes) out.exactBoxes[std::size_t(self) * kCwbvhWidth + s] = ch.box;
    if (!isLeafRef(ch.ref)) {
      n.meta[s] = kCwbvhInterior;
      out.starts[childBase + rank] = ch.ref;
      if (out.parentSlot) out.parentSlot[childBase + rank] = self * kCwbvhWidth + s;
      ++rank;
      continue;
    }
    n.meta[s] = uint8_t(kCwbvhLeaf | offset);
    cwbvhCopyLeafTriangles(t, ch.ref, ch.count, out.triIndex + triBase + offset);
    offset += ch.count;
  }
  n.triCount = uint8_t(offset);
  cwbvhQuantize(n, boxes);
#if defined(__CUDA_ARCH__)
  const uint4* src = reinterpret_cast<const uint4*>(&n);
  uint4* dst = reinterpret_cast<uint4*>(out.nodes + self);
#pragma unroll
  for (int k = 0; k < 5; ++k) dst[k] = src[k];
#else
  out.nodes[self] = n;
#endif
}

// Host emulation of the GPU conversion (the same steps, serially, level by level): the
// compressed layout of the binary tree `t` whose root is `rootRef` (a leaf reference with
// rootCount triangles for a tree that is one leaf) with box rootBox. The result always has a root
// node (rootRef 0; a one-leaf tree becomes a node with one leaf child), exactBoxes (the binary
// tree's child boxes), parentSlot, leaves and depth, so validateCwbvh and refitCwbvh apply.
// Throws tsah::DataError when t is not a valid binary tree over its triangles or a node's leaves
// would hold more than 64 triangles. mergeLimit <= kCwbvhMaxLeafTriangles.
CwbvhTree convertToCwbvh(const BinaryTreeView& t, int32_t rootRef, uint32_t rootCount, const Aabb& rootBox,
                         uint32_t mergeLimit = kCwbvhDefaultMergeTriangles);
// The same for frame `frame`'s boxes of a flat tree (canonical or not).
CwbvhTree convertToCwbvh(const FlatBvh& flat, uint32_t frame = 0, uint32_t mergeLimit = kCwbvhDefaultMergeTriangles);

}  // namespace tsah
