#pragma once
// SIMD traversal of the wide layouts (wide_layout.hpp) on the CPU: closest hit and any hit
// (occlusion: stops at the first hit found); closest hit visits the entered children near-first,
// any hit in the order the caller picks (AnyHitOrder: farthest first, or the tree's order).
//
// The kernels are compiled once per instruction set, each in its own file with its own compiler
// flags (libtsah/src/wide_kernels_<isa>.cpp, all from one template, wide_kernels.inl):
//   sse:    4-wide nodes with SSE2 (every x86-64 runs it)
//   avx2:   4-wide with VEX-encoded SSE, 8-wide with AVX2
//   avx512: the same widths with AVX-512VL (mask registers for the compares; 32 vector registers)
// and chosen at run time in ONE place (wideKernels(), by __builtin_cpu_supports), so a binary built
// for plain x86-64 still runs everywhere. Results equal the binary traversal's (traversal.hpp):
// the box and Woop tests do the same float operations in the same order (no FMA contraction), with
// the same watertight fallback near edges; only a tie between two triangles at exactly the same
// distance may resolve to the other triangle.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tsah/core/kinds.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/wide_layout.hpp"

namespace tsah {


// The order in which an any-hit (occlusion) traversal visits the children a ray enters. The answer
// is the same either way; only how soon the first hit is found, and the cost of ordering, differ.
enum class AnyHitOrder : uint8_t {
  // Sorted by entry distance, farthest first: rays leaving a surface whose occluder lies across a
  // gap (shadow rays toward a light: the wall or ceiling between the surface and the light).
  FarthestFirst = 0,
  // No sort: the node's child order (the binary tree's), last child first. For short rays (ambient
  // occlusion): the children they enter mostly contain the origin, so the entry distances tie and
  // sorting them is wasted work.
  TreeOrder = 1,
};

// SimdIsa and its names ("sse", "avx2", "avx512"): core/kinds.hpp.
// True when the kernels for isa are compiled into this build and the processor runs them.
bool isaSupported(SimdIsa isa);
// Every supported instruction set, the best last; and the best one.
std::vector<SimdIsa> supportedIsas();
SimdIsa bestIsa();

// The entry points of one instruction set; a width without kernels has null pointers (sse has no
// 8-wide kernels).
struct WideKernels {
  SimdIsa isa = SimdIsa::Sse;
  Hit (*closest4)(const WideView<4>& bvh, const Ray& ray) = nullptr;
  bool (*any4)(const WideView<4>& bvh, const Ray& ray, AnyHitOrder order) = nullptr;
  Hit (*closest8)(const WideView<8>& bvh, const Ray& ray) = nullptr;
  bool (*any8)(const WideView<8>& bvh, const Ray& ray, AnyHitOrder order) = nullptr;
  // The same at a blurred frame's time (WideMotionFrame): lerped child boxes and triangles.
  Hit (*closestMotion4)(const WideView<4>& bvh, const WideMotionFrame<4>& m, const Ray& ray) = nullptr;
  bool (*anyMotion4)(const WideView<4>& bvh, const WideMotionFrame<4>& m, const Ray& ray, AnyHitOrder order) = nullptr;
  Hit (*closestMotion8)(const WideView<8>& bvh, const WideMotionFrame<8>& m, const Ray& ray) = nullptr;
  bool (*anyMotion8)(const WideView<8>& bvh, const WideMotionFrame<8>& m, const Ray& ray, AnyHitOrder order) = nullptr;
  // The refit's inner step (WideTree::refit), in every table: the Woop rows of one packet whose
  // lane l < lanes holds the triangle of vertex indices vertices[3l], [3l + 1], [3l + 2] (xyz per
  // vertex in `positions`), bit for bit makeWoopTriangle's (lanes from `lanes` on and degenerate
  // triangles get zero rows), and in `bounds` the box of those triangles' vertices (NaN
  // coordinates skipped). 1 <= lanes <= N; vertices past lane lanes - 1 are not read.
  void (*woopRows4)(const float* positions, const uint32_t* vertices, uint32_t lanes, WoopPacket<4>& packet,
                    Aabb& bounds) = nullptr;
  void (*woopRows8)(const float* positions, const uint32_t* vertices, uint32_t lanes, WoopPacket<8>& packet,
                    Aabb& bounds) = nullptr;
  // The blurred refit's step (WideTree::refitKey), in every table: as woopRows, but the lanes'
  // vertices into a KeyVertexPacket (padding lanes repeat lane 0's) instead of Woop rows.
  void (*keyVertices4)(const float* positions, const uint32_t* vertices, uint32_t lanes, KeyVertexPacket<4>& out,
                       Aabb& bounds) = nullptr;
  void (*keyVertices8)(const float* positions, const uint32_t* vertices, uint32_t lanes, KeyVertexPacket<8>& out,
                       Aabb& bounds) = nullptr;
};

// The kernels of isa; throws tsah::ConfigError when it is not supported (isaSupported).
const WideKernels& wideKernels(SimdIsa isa);

}  // namespace tsah
