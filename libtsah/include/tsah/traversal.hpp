#pragma once
// Stack-based traversal of the GPU-ready binary BVH (gpu_layout.hpp): closest hit for primary rays,
// any hit for occlusion (ambient occlusion, shadows). Written against a trivially copyable view so
// that the same code runs on the CPU and, compiled by nvcc, on the GPU.
#include <cstdint>

#include "tsah/gpu_layout.hpp"
#include "tsah/hd.hpp"
#include "tsah/ray.hpp"
#include "tsah/woop.hpp"

namespace tsah {

// Traversal needs one stack entry per tree level; trees deeper than this are refused up front by
// the runtimes (CpuRuntime checks FlatBvh::depth).
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
};

namespace detail {

// Tests the triangles of one leaf; returns true when one was hit (and, for closest hit, shortened tmax).
template <bool AnyHit>
TSAH_HD bool intersectLeaf(const BvhView& bvh, const Ray& ray, const RayPrep& prep, uint32_t first, uint32_t count,
                           float& tmax, Hit& hit) {
  bool found = false;
  for (uint32_t s = first; s < first + count; ++s) {
    float t, u, v;
    auto fetch = [&](Vec3& v0, Vec3& v1, Vec3& v2) {
      const uint32_t* tri = bvh.indices + 3 * std::size_t(bvh.triIndex[s]);
      v0 = bvh.vertex(tri[0]);
      v1 = bvh.vertex(tri[1]);
      v2 = bvh.vertex(tri[2]);
    };
    if (intersectTriangle(ray, prep, bvh.woop[s], tmax, fetch, t, u, v)) {
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

template <bool AnyHit>
TSAH_HD Hit traverse(const BvhView& bvh, const Ray& ray) {
  Hit hit;
  const RayPrep prep = prepareRay(ray);
  float tmax = ray.tmax;
  float tEntry;
  if (bvh.rootCount == 0 && isLeafRef(bvh.rootRef)) return hit;  // empty tree
  if (!intersectBox(prep, bvh.rootBox, ray.tmin, tmax, tEntry)) return hit;
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
      const GpuBvhNode& node = bvh.nodes[ref];
      float t0, t1;
      const bool hit0 = intersectBox(prep, node.childBox(0), ray.tmin, tmax, t0);
      const bool hit1 = intersectBox(prep, node.childBox(1), ray.tmin, tmax, t1);
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

}  // namespace tsah
