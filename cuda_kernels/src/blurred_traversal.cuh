#pragma once
// Traversal of a blurred frame in the binary layout (docs/cuda-runtime.md, motion blur): every key
// of the shutter holds a full set of node boxes and vertex positions; a ray at shutter fraction tau
// tests the child boxes lerped between the two keys of tau's segment (padded outward against float
// rounding) and the triangle whose vertices are lerped the same way, with the watertight test.
#include "blurred_trace.hpp"
#include "device_types.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah::cuda::detail {

// Segment and blend of tau: the last key with key[s] <= tau (the last segment for tau = 1), f
// clamped to [0, 1]. Stand-in for the shared lookup of tsah/layout/motion_blur.hpp.
struct KeyBlend {
  uint32_t s;
  float f;
};
__device__ __forceinline__ KeyBlend keyBlend(const float* keyTimes, uint32_t keys, float tau) {
  uint32_t s = 0;
  while (s + 2 < keys && keyTimes[s + 1] <= tau) ++s;
  const float f = (tau - keyTimes[s]) / (keyTimes[s + 1] - keyTimes[s]);
  return {s, fminf(fmaxf(f, 0.0f), 1.0f)};
}

__device__ __forceinline__ float lerpKey(float a, float b, float f) { return a + f * (b - a); }

// The lerp of a box bound with an outward pad: the rounding of a + f*(b-a) is below 3 units in the
// last place of max(|a|, |b|), for the box and for each vertex, so 2^-20 of it covers both.
__device__ __forceinline__ float lerpLo(float a, float b, float f) {
  return lerpKey(a, b, f) - (fmaxf(fabsf(a), fabsf(b)) * 9.5367432e-7f + 1e-37f);
}
__device__ __forceinline__ float lerpHi(float a, float b, float f) {
  return lerpKey(a, b, f) + (fmaxf(fabsf(a), fabsf(b)) * 9.5367432e-7f + 1e-37f);
}

__device__ __forceinline__ Aabb lerpBox(const Aabb& a, const Aabb& b, float f) {
  Aabb r;
  r.lo = {lerpLo(a.lo.x, b.lo.x, f), lerpLo(a.lo.y, b.lo.y, f), lerpLo(a.lo.z, b.lo.z, f)};
  r.hi = {lerpHi(a.hi.x, b.hi.x, f), lerpHi(a.hi.y, b.hi.y, f), lerpHi(a.hi.z, b.hi.z, f)};
  return r;
}

__device__ __forceinline__ Vec3 lerpVertex(const float* p0, const float* p1, uint32_t v, float f) {
  const float* a = p0 + 3 * std::size_t(v);
  const float* b = p1 + 3 * std::size_t(v);
  return {lerpKey(__ldg(a), __ldg(b), f), lerpKey(__ldg(a + 1), __ldg(b + 1), f), lerpKey(__ldg(a + 2), __ldg(b + 2), f)};
}

// One ray at shutter fraction tau; the closest hit (triangle id) or, AnyHit, the first hit found.
template <bool AnyHit>
__device__ Hit blurredTrace(const BlurredScene& scene, const Ray& ray, float tau) {
  const KeyBlend kb = keyBlend(scene.keyTimes, scene.keys, tau);
  const GpuBvhNode* n0 = scene.keyNodes + std::size_t(kb.s) * scene.interiorCount;
  const GpuBvhNode* n1 = n0 + scene.interiorCount;
  const float* p0 = scene.keyPositions + kb.s * scene.vertexCoords;
  const float* p1 = p0 + scene.vertexCoords;
  const RayPrep prep = prepareRay(ray);
  Hit hit{};
  float hitT = ray.tmax, t;
  const RootInfo& root = scene.keyRoots[kb.s];
  if (!intersectBox(prep, lerpBox(root.box, scene.keyRoots[kb.s + 1].box, kb.f), ray.tmin, hitT, t)) return hit;
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
      const bool hit0 = intersectBox(prep, lerpBox(a.childBox(0), b.childBox(0), kb.f), ray.tmin, hitT, t0);
      const bool hit1 = intersectBox(prep, lerpBox(a.childBox(1), b.childBox(1), kb.f), ray.tmin, hitT, t1);
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
      if (intersectWatertight(prep, lerpVertex(p0, p1, __ldg(v), kb.f), lerpVertex(p0, p1, __ldg(v + 1), kb.f),
                              lerpVertex(p0, p1, __ldg(v + 2), kb.f), ray.tmin, hitT, t, u, w)) {
        hitT = t;
        hit = Hit{t, u, w, tri};
        if constexpr (AnyHit) return hit;
      }
    }
  }
  return hit;
}

}  // namespace tsah::cuda::detail
