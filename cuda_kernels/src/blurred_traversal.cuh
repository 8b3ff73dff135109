#pragma once
// Traversal of a blurred frame in the binary layout (docs/cuda-runtime.md, motion blur): every key
// of the shutter holds a full set of node boxes and vertex positions; a ray at shutter fraction tau
// tests the child boxes lerped between the two keys of tau's segment (padded outward against float
// rounding) and the triangle whose vertices are lerped the same way, with the watertight test: the
// segment lookup, the lerps and the pad are tsah/layout/motion_blur.hpp's, as on the CPU.
#include "blurred_trace.hpp"
#include "device_types.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah::cuda::detail {

__device__ __forceinline__ Vec3 loadVertex(const float* p, uint32_t v) {
  const float* q = p + 3 * std::size_t(v);
  return {__ldg(q), __ldg(q + 1), __ldg(q + 2)};
}

// Vertex v at blend f of the segment whose keys' positions are p0 and p1.
__device__ __forceinline__ Vec3 vertexAt(const float* p0, const float* p1, uint32_t v, float f) {
  return motion::lerpVertex(loadVertex(p0, v), loadVertex(p1, v), f);
}

// One ray at shutter fraction tau; the closest hit (triangle id) or, AnyHit, the first hit found.
template <bool AnyHit>
__device__ Hit blurredTrace(const BlurredScene& scene, const Ray& ray, float tau) {
  const motion::Segment kb = motion::segmentAt(scene.keyTimes, int(scene.keys), tau);
  const GpuBvhNode* n0 = scene.keyNodes + std::size_t(kb.index) * scene.interiorCount;
  const GpuBvhNode* n1 = n0 + scene.interiorCount;
  const float* p0 = scene.keyPositions + uint64_t(kb.index) * scene.vertexCoords;
  const float* p1 = p0 + scene.vertexCoords;
  const RayPrep prep = prepareRay(ray);
  Hit hit{};
  float hitT = ray.tmax, t;
  const RootInfo& root = scene.keyRoots[kb.index];
  if (!intersectBox(prep, motion::lerpBox(root.box, scene.keyRoots[kb.index + 1].box, kb.f), ray.tmin, hitT, t)) return hit;
  int2 stack[kTraversalStackSize + 1];
  int sp = 0;
  stack[sp++] = make_int2(root.ref, int(root.count));
  while (sp > 0) {
    const int2 top = stack[--sp];
    int32_t ref = top.x;
    uint32_t count = uint32_t(top.y);
    while (!isLeafRef(ref)) {
      const GpuBvhNode a = n0[ref], b = n1[ref];
      float t0, t1;
      const bool hit0 = intersectBox(prep, motion::lerpBox(a.childBox(0), b.childBox(0), kb.f), ray.tmin, hitT, t0);
      const bool hit1 = intersectBox(prep, motion::lerpBox(a.childBox(1), b.childBox(1), kb.f), ray.tmin, hitT, t1);
      if (!hit0 && !hit1) {
        count = 0;
        break;
      }
      const bool firstIs1 = !hit0 || (hit1 && t1 < t0);
      if (hit0 && hit1) stack[sp++] = firstIs1 ? make_int2(a.ref0, int(a.count0)) : make_int2(a.ref1, int(a.count1));
      ref = firstIs1 ? a.ref1 : a.ref0;
      count = firstIs1 ? a.count1 : a.count0;
    }
    const uint32_t first = leafFirstSlot(ref);
    for (uint32_t s = first; s < first + count; ++s) {
      const uint32_t tri = __ldg(scene.triIndex + s);
      const uint32_t* v = scene.indices + 3 * std::size_t(tri);
      float u, w;
      if (intersectWatertight(prep, vertexAt(p0, p1, __ldg(v), kb.f), vertexAt(p0, p1, __ldg(v + 1), kb.f),
                              vertexAt(p0, p1, __ldg(v + 2), kb.f), ray.tmin, hitT, t, u, w)) {
        hitT = t;
        hit = Hit{t, u, w, tri};
        if constexpr (AnyHit) return hit;
      }
    }
  }
  return hit;
}

}  // namespace tsah::cuda::detail
