#pragma once
// Stack-based traversal of the GPU-ready binary BVH (gpu_layout.hpp): closest hit for primary rays,
// any hit for occlusion (ambient occlusion, shadows). Written against a trivially copyable view so
// that the same code runs on the CPU and, compiled by nvcc, on the GPU.
#include <cstdint>

#if !defined(__CUDACC__) && (defined(__SSE2__) || defined(_M_X64))
#include <emmintrin.h>
#define TSAH_TRAVERSAL_SSE 1
#endif

#include "tsah/layout/gpu_layout.hpp"
#include "tsah/core/hd.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah {

// Traversal needs one stack entry per tree level; trees deeper than this are refused up front by
// the runtimes (CpuRuntime checks FlatBvh::depth). Every tree the library makes fits: kMaxBvhDepth.
inline constexpr uint32_t kTraversalStackSize = 128;

// Everything a traversal reads for one frame. Raw pointers and counts only: pass by value.
struct BvhView {
  const GpuBvhNode* nodes = nullptr;    // interior nodes, canonical order
  const WoopTriangle* woop = nullptr;   // per slot
  const uint32_t* triIndex = nullptr;   // slot -> triangle id
  const uint32_t* indices = nullptr;    // 3 vertex indices per triangle id
  const float* positions = nullptr;     // xyz per vertex, this frame
  int32_t rootRef = makeLeafRef(0);
  uint32_t rootCount = 0;
  Aabb rootBox;

  TSAH_HD Vec3 vertex(uint32_t i) const { return {positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]}; }

  // What the shared traversal loop reads (detail::traverse): the root box, a node, a slot's test.
  TSAH_HD const Aabb& root() const { return rootBox; }
  TSAH_HD const GpuBvhNode& node(int32_t ref) const { return nodes[ref]; }
  TSAH_HD bool intersectSlot(const Ray& ray, const RayPrep& prep, uint32_t s, float tmax, float& t, float& u,
                             float& v) const {
    auto fetch = [&](Vec3& v0, Vec3& v1, Vec3& v2) {
      const uint32_t* tri = indices + 3 * std::size_t(triIndex[s]);
      v0 = vertex(tri[0]);
      v1 = vertex(tri[1]);
      v2 = vertex(tri[2]);
    };
    return intersectTriangle(ray, prep, woop[s], tmax, fetch, t, u, v);
  }
};

// A blurred frame (docs/motion-blur.md): the tree refitted at every key of the shutter. Raw
// pointers and counts only: pass by value.
struct MotionBvhView {
  const GpuBvhNode* keyNodes = nullptr;  // keyCount blocks of nodeCount interior nodes, one per key
  const Aabb* keyRootBoxes = nullptr;    // per key
  const float* keyPositions = nullptr;   // keyCount blocks of vertexCount * 3 floats
  const float* keyTimes = nullptr;       // shutter fractions: first 0, last 1, increasing
  uint32_t keyCount = 0, nodeCount = 0, vertexCount = 0;
  const uint32_t* triIndex = nullptr;  // slot -> triangle id
  const uint32_t* indices = nullptr;   // 3 vertex indices per triangle id
  int32_t rootRef = makeLeafRef(0);
  uint32_t rootCount = 0;
};

// A binary node at f between its refits at keys s (n0) and s + 1 (n1): each child box lerped and
// padded (motion::lerpBox), the references n0's.
TSAH_HD GpuBvhNode lerpNode(const GpuBvhNode& n0, const GpuBvhNode& n1, float f) {
  GpuBvhNode n = n0;
  for (int c = 0; c < 2; ++c) n.setChildBox(c, motion::lerpBox(n0.childBox(c), n1.childBox(c), f));
  return n;
}

// One ray's view of a blurred frame: boxes and triangles lerped between the two keys of its time's
// segment (the same loop as the instant frame; only what it reads differs).
struct MotionFrame {
  const GpuBvhNode* nodes0;
  const GpuBvhNode* nodes1;
  const float* positions0;
  const float* positions1;
  const uint32_t* triIndex;
  const uint32_t* indices;
  int32_t rootRef;
  uint32_t rootCount;
  float f;
  Aabb rootBox;

  TSAH_HD MotionFrame(const MotionBvhView& m, float time) {
    const motion::Segment seg = motion::segmentAt(m.keyTimes, int(m.keyCount), time);
    const uint32_t k0 = uint32_t(seg.index), k1 = m.keyCount > 1 ? k0 + 1 : k0;
    nodes0 = m.keyNodes + std::size_t(k0) * m.nodeCount;
    nodes1 = m.keyNodes + std::size_t(k1) * m.nodeCount;
    positions0 = m.keyPositions + std::size_t(k0) * m.vertexCount * 3;
    positions1 = m.keyPositions + std::size_t(k1) * m.vertexCount * 3;
    triIndex = m.triIndex;
    indices = m.indices;
    rootRef = m.rootRef;
    rootCount = m.rootCount;
    f = seg.f;
    rootBox = motion::lerpBox(m.keyRootBoxes[k0], m.keyRootBoxes[k1], f);
  }

  TSAH_HD const Aabb& root() const { return rootBox; }
  TSAH_HD GpuBvhNode node(int32_t ref) const { return lerpNode(nodes0[ref], nodes1[ref], f); }
  TSAH_HD Vec3 vertex(uint32_t i) const {
    const Vec3 a{positions0[3 * i], positions0[3 * i + 1], positions0[3 * i + 2]};
    const Vec3 b{positions1[3 * i], positions1[3 * i + 1], positions1[3 * i + 2]};
    return motion::lerpVertex(a, b, f);
  }
  // The watertight test on the lerped vertices (no Woop triangles for a blurred frame).
  TSAH_HD bool intersectSlot(const Ray& ray, const RayPrep& prep, uint32_t s, float tmax, float& t, float& u,
                             float& v) const {
    const uint32_t* tri = indices + 3 * std::size_t(triIndex[s]);
    return intersectWatertight(prep, vertex(tri[0]), vertex(tri[1]), vertex(tri[2]), ray.tmin, tmax, t, u, v);
  }
};

// Slab tests of both children of a node: bit 0 / bit 1 set when child 0 / 1 is entered within
// [tmin, tmax], with the entry distances in t0 and t1. Exactly intersectBox() on each child
// (the SSE path performs the same operations in the same order, so results are bit-identical).
struct NodeRayPrep {
#if defined(TSAH_TRAVERSAL_SSE)
  __m128 oxy, ixy, oz, iz;
#endif
  RayPrep ray;
};

TSAH_HD NodeRayPrep prepareNodeRay(const RayPrep& r) {
  NodeRayPrep p;
  p.ray = r;
#if defined(TSAH_TRAVERSAL_SSE)
  p.oxy = _mm_setr_ps(r.org.x, r.org.x, r.org.y, r.org.y);
  p.ixy = _mm_setr_ps(r.invDir.x, r.invDir.x, r.invDir.y, r.invDir.y);
  p.oz = _mm_set1_ps(r.org.z);
  p.iz = _mm_set1_ps(r.invDir.z);
#endif
  return p;
}

TSAH_HD int intersectChildren(const NodeRayPrep& p, const GpuBvhNode& node, float tmin, float tmax, float& t0,
                              float& t1) {
#if defined(TSAH_TRAVERSAL_SSE)
  const __m128 a = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(&node.c0loX), p.oxy), p.ixy);  // x0l x0h y0l y0h
  const __m128 b = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(&node.c1loX), p.oxy), p.ixy);  // x1l x1h y1l y1h
  const __m128 c = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(&node.c0loZ), p.oz), p.iz);    // z0l z0h z1l z1h
  const __m128 lo = _mm_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0));  // x0l y0l x1l y1l
  const __m128 hi = _mm_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1));  // x0h y0h x1h y1h
  const __m128 mn = _mm_min_ps(lo, hi), mx = _mm_max_ps(lo, hi);
  const __m128 zlo = _mm_shuffle_ps(c, c, _MM_SHUFFLE(2, 0, 2, 0));  // z0l z1l . .
  const __m128 zhi = _mm_shuffle_ps(c, c, _MM_SHUFFLE(3, 1, 3, 1));  // z0h z1h . .
  // Lanes 0 and 1 hold child 0 and child 1.
  const __m128 nearXY = _mm_max_ps(_mm_shuffle_ps(mn, mn, _MM_SHUFFLE(2, 0, 2, 0)),
                                   _mm_shuffle_ps(mn, mn, _MM_SHUFFLE(3, 1, 3, 1)));
  const __m128 farXY = _mm_min_ps(_mm_shuffle_ps(mx, mx, _MM_SHUFFLE(2, 0, 2, 0)),
                                  _mm_shuffle_ps(mx, mx, _MM_SHUFFLE(3, 1, 3, 1)));
  const __m128 nearZ = _mm_max_ps(_mm_min_ps(zlo, zhi), _mm_set1_ps(tmin));
  const __m128 farZ = _mm_min_ps(_mm_max_ps(zlo, zhi), _mm_set1_ps(tmax));
  const __m128 tn = _mm_max_ps(nearXY, nearZ);
  const __m128 tf = _mm_mul_ps(_mm_min_ps(farXY, farZ), _mm_set1_ps(kSlabFarScale));
  alignas(16) float entry[4];
  _mm_store_ps(entry, tn);
  t0 = entry[0];
  t1 = entry[1];
  return _mm_movemask_ps(_mm_cmple_ps(tn, tf)) & 3;
#else
  const bool hit0 = intersectBox(p.ray, node.childBox(0), tmin, tmax, t0);
  const bool hit1 = intersectBox(p.ray, node.childBox(1), tmin, tmax, t1);
  return (hit0 ? 1 : 0) | (hit1 ? 2 : 0);
#endif
}

namespace detail {

// Tests the triangles of one leaf; returns true when one was hit (and, for closest hit, shortened tmax).
template <bool AnyHit, typename Frame>
TSAH_HD bool intersectLeaf(const Frame& bvh, const Ray& ray, const RayPrep& prep, uint32_t first, uint32_t count,
                           float& tmax, Hit& hit) {
  bool found = false;
  for (uint32_t s = first; s < first + count; ++s) {
    float t, u, v;
    if (bvh.intersectSlot(ray, prep, s, tmax, t, u, v)) {
      found = true;
      tmax = t;
      hit.t = t;
      hit.u = u;
      hit.v = v;
      hit.tri = bvh.triIndex[s];
      if (AnyHit) return true;
    }
  }
  return found;
}

// The one traversal loop; Frame supplies the root box, the nodes and the triangle test (BvhView:
// the instant frame; MotionFrame: a blurred frame at one ray's time).
template <bool AnyHit, typename Frame>
TSAH_HD Hit traverse(const Frame& bvh, const Ray& ray) {
  Hit hit;
  const RayPrep prep = prepareRay(ray);
  const NodeRayPrep nodePrep = prepareNodeRay(prep);
  float tmax = ray.tmax;
  float tEntry;
  if (bvh.rootCount == 0 && isLeafRef(bvh.rootRef)) return hit;  // empty tree
  if (!intersectBox(prep, bvh.root(), ray.tmin, tmax, tEntry)) return hit;
  if (isLeafRef(bvh.rootRef)) {
    intersectLeaf<AnyHit>(bvh, ray, prep, leafFirstSlot(bvh.rootRef), bvh.rootCount, tmax, hit);
    return hit;
  }
  // Stack of (reference, leaf count); the near child is visited first, the far one pushed.
  int32_t stackRef[kTraversalStackSize];
  uint32_t stackCount[kTraversalStackSize];
  float stackEntry[kTraversalStackSize];  // entry distance of the pushed box: skip it once tmax is nearer
  uint32_t sp = 0;
  int32_t ref = bvh.rootRef;
  uint32_t count = 0;
  for (;;) {
    if (isLeafRef(ref)) {
      if (intersectLeaf<AnyHit>(bvh, ray, prep, leafFirstSlot(ref), count, tmax, hit) && AnyHit) return hit;
    } else {
      const auto& node = bvh.node(ref);  // a reference, or the lerped node (lifetime extended)
      float t0, t1;
      const int mask = intersectChildren(nodePrep, node, ray.tmin, tmax, t0, t1);
      const bool hit0 = (mask & 1) != 0, hit1 = (mask & 2) != 0;
      if (hit0 && hit1) {
        const bool swap = t1 < t0;
        const int nearC = swap ? 1 : 0, farC = swap ? 0 : 1;
        stackRef[sp] = node.childRef(farC);
        stackCount[sp] = node.childCount(farC);
        stackEntry[sp] = swap ? t0 : t1;
        ++sp;
        ref = node.childRef(nearC);
        count = node.childCount(nearC);
        continue;
      }
      if (hit0 || hit1) {
        const int c = hit0 ? 0 : 1;
        ref = node.childRef(c);
        count = node.childCount(c);
        continue;
      }
    }
    do {
      if (sp == 0) return hit;
      --sp;
    } while (stackEntry[sp] > tmax * kSlabFarScale);
    ref = stackRef[sp];
    count = stackCount[sp];
  }
}

}  // namespace detail

// Nearest hit in (ray.tmin, ray.tmax); hit.tri == kNoHit when there is none.
TSAH_HD Hit closestHit(const BvhView& bvh, const Ray& ray) { return detail::traverse<false>(bvh, ray); }

// True when anything is hit in (ray.tmin, ray.tmax) (occlusion).
TSAH_HD bool anyHit(const BvhView& bvh, const Ray& ray) { return detail::traverse<true>(bvh, ray).valid(); }

// The same in a blurred frame at the ray's time (shutter fraction in [0, 1]).
TSAH_HD Hit closestHit(const MotionBvhView& bvh, const Ray& ray, float time) {
  return detail::traverse<false>(MotionFrame(bvh, time), ray);
}
TSAH_HD bool anyHit(const MotionBvhView& bvh, const Ray& ray, float time) {
  return detail::traverse<true>(MotionFrame(bvh, time), ray).valid();
}

}  // namespace tsah
