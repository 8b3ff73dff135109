#pragma once
// The wide (N = 4 or 8) BVH layout shared by the per-frame refit and the SIMD traversals, and
// written by `tsah export --layout bvh4|bvh8` (docs/wide-bvh.md is the byte-level spec).
// Plain data, one definition for every user.
//
// A node holds its N child boxes as structure-of-arrays, so one SIMD operation handles one plane
// of all children: box[0..2] are lo.x, lo.y, lo.z and box[3..5] hi.x, hi.y, hi.z, N floats each.
// A child reference ref >= 0 is an interior node (count 0); ref < 0 a leaf whose triangles are
// packed N at a time in the Woop packets [~ref, ~ref + ceil(count / N)); count is the leaf's
// triangle count. Unused child slots hold the empty box (lo = +3.4e38, hi = -3.4e38; no ray enters
// it: see below), ref 0 and count 0; the used ones come first.
//
// A Woop packet holds the rows of N Woop triangles (woop.hpp) as structure-of-arrays:
// row[4 * r + c][lane] is component c (x, y, z, w) of row r (0..2) of the lane's triangle, and
// slot[lane] its triangle slot (the index into the triangle index array, which maps slots to the
// animation's triangle ids, as in the binary layout). Lanes past a leaf's count are padding: zero
// rows (which never hit) and the slot of the leaf's first triangle.
//
// A tree in the Vertices form (TriangleForm) has no Woop packets: its leaf references index its
// KeyVertexPackets (one per would-be Woop packet, the same lanes) and packetSlots instead.
//
// Traversals pick each axis's near plane by the sign of the ray direction (box[a] for a positive
// inverse direction, box[3 + a] otherwise); with the empty box the entry distance is then +inf or
// the exit distance -inf, so empty slots are never entered.
#include <cstdint>
#include <type_traits>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/gpu_layout.hpp"  // child reference helpers: isLeafRef, leafFirstSlot, makeLeafRef
#include "tsah/core/hd.hpp"
#include "tsah/core/kinds.hpp"  // TriangleForm
#include "tsah/layout/woop.hpp"

namespace tsah {

template <uint32_t N>
struct alignas(N >= 8 ? 32 : 16) WideSoaNode {
  static_assert(N == 4 || N == 8, "wide layouts are 4 or 8 wide");
  float box[6][N];    // lo.x, lo.y, lo.z, hi.x, hi.y, hi.z of each child
  int32_t ref[N];     // child references (see above)
  uint32_t count[N];  // leaf triangle counts, 0 for interior children and unused slots

  TSAH_HD Aabb childBox(uint32_t c) const {
    Aabb b;
    b.lo = {box[0][c], box[1][c], box[2][c]};
    b.hi = {box[3][c], box[4][c], box[5][c]};
    return b;
  }
  TSAH_HD void setChildBox(uint32_t c, const Aabb& b) {
    box[0][c] = b.lo.x, box[1][c] = b.lo.y, box[2][c] = b.lo.z;
    box[3][c] = b.hi.x, box[4][c] = b.hi.y, box[5][c] = b.hi.z;
  }
  // The union of the used children's boxes (unused slots hold the empty box, the identity).
  TSAH_HD Aabb bounds() const {
    Aabb b;
    for (uint32_t c = 0; c < N; ++c) b.extend(childBox(c));
    return b;
  }
};

template <uint32_t N>
struct alignas(N >= 8 ? 32 : 16) WoopPacket {
  static_assert(N == 4 || N == 8, "wide layouts are 4 or 8 wide");
  float row[12][N];   // r0.x r0.y r0.z r0.w r1.x ... r2.w, one lane per triangle
  uint32_t slot[N];   // triangle slot of each lane

  TSAH_HD void set(uint32_t lane, const WoopTriangle& w, uint32_t triangleSlot) {
    const Float4* rows[3] = {&w.r0, &w.r1, &w.r2};
    for (int r = 0; r < 3; ++r) {
      row[4 * r + 0][lane] = rows[r]->x;
      row[4 * r + 1][lane] = rows[r]->y;
      row[4 * r + 2][lane] = rows[r]->z;
      row[4 * r + 3][lane] = rows[r]->w;
    }
    slot[lane] = triangleSlot;
  }
  TSAH_HD WoopTriangle get(uint32_t lane) const {
    WoopTriangle w;
    Float4* rows[3] = {&w.r0, &w.r1, &w.r2};
    for (int r = 0; r < 3; ++r)
      *rows[r] = {row[4 * r][lane], row[4 * r + 1][lane], row[4 * r + 2][lane], row[4 * r + 3][lane]};
    return w;
  }
};

// A blurred frame's triangles at one key, one record per Woop packet (the same lanes):
// vertex[3 * k + a][lane] is coordinate a (x, y, z) of vertex k (0..2) of the lane's triangle at the
// key. Padding lanes repeat lane 0's triangle. The blurred leaf test lerps two keys' records lane
// by lane instead of gathering each vertex through the index array.
template <uint32_t N>
struct alignas(N >= 8 ? 32 : 16) KeyVertexPacket {
  static_assert(N == 4 || N == 8, "wide layouts are 4 or 8 wide");
  float vertex[9][N];

  TSAH_HD Vec3 get(uint32_t k, uint32_t lane) const {
    return {vertex[3 * k][lane], vertex[3 * k + 1][lane], vertex[3 * k + 2][lane]};
  }
};

static_assert(sizeof(WideSoaNode<4>) == 128 && alignof(WideSoaNode<4>) == 16);
static_assert(sizeof(WideSoaNode<8>) == 256 && alignof(WideSoaNode<8>) == 32);
static_assert(sizeof(WoopPacket<4>) == 208 && alignof(WoopPacket<4>) == 16);
static_assert(sizeof(WoopPacket<8>) == 416 && alignof(WoopPacket<8>) == 32);
static_assert(sizeof(KeyVertexPacket<4>) == 144 && sizeof(KeyVertexPacket<8>) == 288);
static_assert(std::is_trivially_copyable_v<WideSoaNode<8>> && std::is_standard_layout_v<WideSoaNode<8>>);
static_assert(std::is_trivially_copyable_v<WoopPacket<8>> && std::is_standard_layout_v<WoopPacket<8>>);

// Packets of a leaf of `count` triangles.
template <uint32_t N>
TSAH_HD uint32_t packetCount(uint32_t count) {
  return (count + N - 1) / N;
}

// Everything a wide traversal reads for one frame. Raw pointers and counts only: pass by value.
template <uint32_t N>
struct WideView {
  const WideSoaNode<N>* nodes = nullptr;  // node 0 is the root when rootRef >= 0
  const WoopPacket<N>* packets = nullptr;  // TriangleForm::Woop; null in the Vertices form
  const KeyVertexPacket<N>* vertexPackets = nullptr;  // TriangleForm::Vertices: this frame's, else null
  const uint32_t* packetSlots = nullptr;  // per packet the slot of lane 0 (lane l: packetSlots[p] + l)
  const uint32_t* triIndex = nullptr;     // slot -> triangle id
  const uint32_t* indices = nullptr;      // 3 vertex indices per triangle id
  const uint32_t* slotVertices = nullptr; // 3 vertex indices per slot (those of triIndex[slot]): the
                                          // watertight fallback reads them without the triIndex load
  const float* positions = nullptr;       // xyz per vertex, this frame
  int32_t rootRef = makeLeafRef(0);
  uint32_t rootCount = 0;                 // triangles of a leaf root
  Aabb rootBox;

  TSAH_HD Vec3 vertex(uint32_t i) const { return {positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]}; }
};

// What a blurred frame (docs/motion-blur.md) adds to the WideView of key s for one ray: the nodes
// of key s + 1, the triangles' vertices at both keys (one KeyVertexPacket per Woop packet) and the
// ray's place f between them. The view's nodes and positions are then key s's, and its root box
// lerped at f when the root is a leaf (an interior root's box is not read); neither the Woop
// packets nor the view's vertex packets are read, only packetSlots.
template <uint32_t N>
struct WideMotionFrame {
  const WideSoaNode<N>* nodes1 = nullptr;
  const KeyVertexPacket<N>* vertices0 = nullptr;
  const KeyVertexPacket<N>* vertices1 = nullptr;
  float f = 0.0f;
  // An interior root: a box holding every child box of the root at every time of the segment
  // (motion::segmentBounds of the keys' root boxes). A ray that misses it finds nothing, so the
  // closest-hit kernels test it first, once, in scalar: most camera rays of a frame where the
  // scene is small miss it.
  Aabb rootBounds;
};

// Traversal stack entries a wide tree of this depth needs at most (one level pushes up to N - 1).
template <uint32_t N>
TSAH_HD uint32_t wideStackNeed(uint32_t depth) {
  return depth * (N - 1) + 1;
}
inline constexpr uint32_t kWideStackSize = 1024;

}  // namespace tsah
