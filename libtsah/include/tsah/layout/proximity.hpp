#pragma once
// Queries beyond rays on the traced layouts: the closest point on the mesh within a radius, and
// the triangles whose box overlaps a query box. One traversal, written against a small adapter per
// layout (the binary view, BvhView, and the wide views, WideView<4|8>), so that the CPU runs it on
// every layout and nvcc compiles the same code for the GPU's binary tree.
//
// Geometry comes from the frame's vertices (indices + positions), not from the Woop triangles, so
// the answers are exact up to float rounding and do not depend on the layout.
#include <cmath>
#include <cstdint>

#include "tsah/core/aabb.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/layout/wide_layout.hpp"

namespace tsah {

// The closest point found for one query: the triangle (kNoHit when none lies within the radius),
// its barycentrics (point = (1 - u - v) v0 + u v1 + v v2), the point and its distance (+inf on a
// miss, with u = v = 0 and the point at the origin).
struct PointHit {
  float distance = HUGE_VALF;
  uint32_t tri = kNoHit;
  float u = 0.0f, v = 0.0f;
  Vec3 point{0.0f, 0.0f, 0.0f};
  TSAH_HD bool valid() const { return tri != kNoHit; }
};

// The point of triangle (a, b, c) closest to p (Ericson, Real-Time Collision Detection 5.1.5), as
// barycentrics u (weight of b) and v (weight of c).
TSAH_HD Vec3 closestPointOnTriangle(Vec3 p, Vec3 a, Vec3 b, Vec3 c, float& u, float& v) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const float d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0.0f && d2 <= 0.0f) return u = 0.0f, v = 0.0f, a;  // vertex a
  const Vec3 bp = p - b;
  const float d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0.0f && d4 <= d3) return u = 1.0f, v = 0.0f, b;  // vertex b
  const float vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f) {  // edge ab
    const float t = d1 / (d1 - d3);
    return u = t, v = 0.0f, a + ab * t;
  }
  const Vec3 cp = p - c;
  const float d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0.0f && d5 <= d6) return u = 0.0f, v = 1.0f, c;  // vertex c
  const float vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f) {  // edge ac
    const float t = d2 / (d2 - d6);
    return u = 0.0f, v = t, a + ac * t;
  }
  const float va = d3 * d6 - d5 * d4;
  if (va <= 0.0f && (d4 - d3) >= 0.0f && (d5 - d6) >= 0.0f) {  // edge bc
    const float t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return u = 1.0f - t, v = t, b + (c - b) * t;
  }
  // Inside the face. A degenerate (zero-area) triangle never gets here: one of the cases above
  // holds for it.
  const float denom = 1.0f / (va + vb + vc);
  u = vb * denom;
  v = vc * denom;
  return a + ab * u + ac * v;
}

// Squared distance from p to box b (0 inside).
TSAH_HD float boxDistanceSquared(Vec3 p, const Aabb& b) {
  float d2 = 0.0f;
  for (int a = 0; a < 3; ++a) {
    const float below = b.lo[a] - p[a], above = p[a] - b.hi[a];
    const float d = below > 0.0f ? below : (above > 0.0f ? above : 0.0f);
    d2 += d * d;
  }
  return d2;
}

// Closed-interval overlap (touching boxes overlap).
TSAH_HD bool boxesOverlap(const Aabb& a, const Aabb& b) {
  return a.lo.x <= b.hi.x && b.lo.x <= a.hi.x && a.lo.y <= b.hi.y && b.lo.y <= a.hi.y && a.lo.z <= b.hi.z &&
         b.lo.z <= a.hi.z;
}

namespace detail {

// Layout adapters: the root, a node's children (box, reference, leaf count) and a leaf's triangles.
struct BinaryQueryTree {
  static constexpr uint32_t kWidth = 2, kStack = kTraversalStackSize;
  BvhView view;
  TSAH_HD Aabb childBox(int32_t ref, uint32_t c) const { return view.nodes[ref].childBox(int(c)); }
  TSAH_HD int32_t childRef(int32_t ref, uint32_t c) const { return view.nodes[ref].childRef(int(c)); }
  TSAH_HD uint32_t childCount(int32_t ref, uint32_t c) const { return view.nodes[ref].childCount(int(c)); }
  TSAH_HD uint32_t leafTriangle(int32_t ref, uint32_t i) const { return view.triIndex[leafFirstSlot(ref) + i]; }
  TSAH_HD const uint32_t* indices() const { return view.indices; }
  TSAH_HD Vec3 vertex(uint32_t i) const { return view.vertex(i); }
};

template <uint32_t N>
struct WideQueryTree {
  static constexpr uint32_t kWidth = N, kStack = kWideStackSize;
  WideView<N> view;
  TSAH_HD Aabb childBox(int32_t ref, uint32_t c) const { return view.nodes[ref].childBox(c); }
  TSAH_HD int32_t childRef(int32_t ref, uint32_t c) const { return view.nodes[ref].ref[c]; }
  TSAH_HD uint32_t childCount(int32_t ref, uint32_t c) const { return view.nodes[ref].count[c]; }
  TSAH_HD uint32_t leafTriangle(int32_t ref, uint32_t i) const {
    return view.triIndex[view.packetSlots[leafFirstSlot(ref) + i / N] + i % N];
  }
  TSAH_HD const uint32_t* indices() const { return view.indices; }
  TSAH_HD Vec3 vertex(uint32_t i) const { return view.vertex(i); }
};

// Box pruning keeps a hair of slack: a triangle's rounded distance may fall a few ulps below the
// rounded distance to the box that holds it.
inline constexpr float kBoxPruneSlack = 1.0f + 1e-5f;

template <class Tree>
TSAH_HD void closestInLeaf(const Tree& tree, Vec3 p, int32_t ref, uint32_t count, float& best2, PointHit& hit) {
  for (uint32_t i = 0; i < count; ++i) {
    const uint32_t tri = tree.leafTriangle(ref, i);
    const uint32_t* v = tree.indices() + 3 * std::size_t(tri);
    float u, w;
    const Vec3 q = closestPointOnTriangle(p, tree.vertex(v[0]), tree.vertex(v[1]), tree.vertex(v[2]), u, w);
    const Vec3 d = q - p;
    const float d2 = dot(d, d);
    // Within the radius; at equal distance the lowest triangle id wins, whatever the layout.
    if (d2 < best2 || (d2 == best2 && tri < hit.tri)) {
      best2 = d2;
      hit.tri = tri, hit.u = u, hit.v = w, hit.point = q;
    }
  }
}

template <class Tree>
TSAH_HD Aabb triangleBox(const Tree& tree, uint32_t tri) {
  const uint32_t* v = tree.indices() + 3 * std::size_t(tri);
  Aabb b;
  b.extend(tree.vertex(v[0]));
  b.extend(tree.vertex(v[1]));
  b.extend(tree.vertex(v[2]));
  return b;
}

}  // namespace detail

// The closest point on the tree's triangles to p within `radius` (distance <= radius); children
// are visited nearest box first and the search radius shrinks to the best distance found.
template <class Tree>
TSAH_HD PointHit closestPoint(const Tree& tree, Aabb rootBox, int32_t rootRef, uint32_t rootCount, Vec3 p,
                              float radius) {
  PointHit hit;
  float best2 = radius * radius;
  if (isLeafRef(rootRef) && rootCount == 0) return hit;  // empty tree
  if (boxDistanceSquared(p, rootBox) > best2 * detail::kBoxPruneSlack) return hit;
  int32_t stackRef[Tree::kStack];
  uint32_t stackCount[Tree::kStack];
  float stackDist[Tree::kStack];
  uint32_t sp = 0;
  stackRef[sp] = rootRef, stackCount[sp] = rootCount, stackDist[sp] = 0.0f, ++sp;
  while (sp > 0) {
    --sp;
    if (stackDist[sp] > best2 * detail::kBoxPruneSlack) continue;
    const int32_t ref = stackRef[sp];
    if (isLeafRef(ref)) {
      detail::closestInLeaf(tree, p, ref, stackCount[sp], best2, hit);
      continue;
    }
    // The children within reach, pushed farthest first so that the nearest is popped next.
    int32_t refs[Tree::kWidth];
    uint32_t counts[Tree::kWidth];
    float dists[Tree::kWidth];
    uint32_t n = 0;
    for (uint32_t c = 0; c < Tree::kWidth; ++c) {
      const Aabb box = tree.childBox(ref, c);
      const float d2 = boxDistanceSquared(p, box);
      if (box.empty() || !(d2 <= best2 * detail::kBoxPruneSlack)) continue;  // empty: an unused wide slot
      uint32_t k = n++;
      for (; k > 0 && dists[k - 1] < d2; --k) refs[k] = refs[k - 1], counts[k] = counts[k - 1], dists[k] = dists[k - 1];
      refs[k] = tree.childRef(ref, c), counts[k] = tree.childCount(ref, c), dists[k] = d2;
    }
    for (uint32_t k = 0; k < n; ++k) stackRef[sp] = refs[k], stackCount[sp] = counts[k], stackDist[sp] = dists[k], ++sp;
  }
  if (hit.valid()) hit.distance = sqrtf(best2);
  return hit;
}

// Calls found(tri) for every triangle whose box (this frame) overlaps `query` (closed intervals),
// in traversal order; returns how many there were.
template <class Tree, class Found>
TSAH_HD uint32_t overlappingTriangles(const Tree& tree, Aabb rootBox, int32_t rootRef, uint32_t rootCount,
                                      const Aabb& query, Found&& found) {
  uint32_t total = 0;
  if (isLeafRef(rootRef) && rootCount == 0) return 0;
  if (!boxesOverlap(rootBox, query)) return 0;
  int32_t stackRef[Tree::kStack];
  uint32_t stackCount[Tree::kStack];
  uint32_t sp = 0;
  stackRef[sp] = rootRef, stackCount[sp] = rootCount, ++sp;
  while (sp > 0) {
    --sp;
    const int32_t ref = stackRef[sp];
    if (isLeafRef(ref)) {
      for (uint32_t i = 0; i < stackCount[sp]; ++i) {
        const uint32_t tri = tree.leafTriangle(ref, i);
        if (boxesOverlap(detail::triangleBox(tree, tri), query)) found(tri), ++total;
      }
      continue;
    }
    for (uint32_t c = 0; c < Tree::kWidth; ++c)
      if (const Aabb box = tree.childBox(ref, c); !box.empty() && boxesOverlap(box, query))
        stackRef[sp] = tree.childRef(ref, c), stackCount[sp] = tree.childCount(ref, c), ++sp;
  }
  return total;
}

}  // namespace tsah
