#pragma once
// The trace of one ray at its shutter time through a blurred two-level frame on the device, written
// once for the batch queries (two_level_blur_trace.cu) and the renderer (two_level_render.cu): the
// TLAS by the binary layout's device loop (bvh2_traversal.cuh) with its key nodes lerped at the
// ray's time, and at a TLAS leaf the instance moved into instance space at that time and traced
// through its pose's blurred BLAS (the flat blurred frame's loop) or its instant BLAS (in the
// runtime's BLAS layout, Form), as
// tsah::TwoLevelRuntime::closestHit(ray, time) does on the CPU. Compile the including file with
// -fmad=false: the lerps, the inverse and the ray's move into instance space round as on the CPU.
#include "blurred_trace.hpp"
#include "bvh2_traversal.cuh"
#include "tsah/core/instance_transform.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/traversal.hpp"
#include "two_level_blur.hpp"
#include "two_level_traversal.cuh"

namespace tsah::cuda::detail {

// One ray's view of a blurred TLAS: the keys s and s + 1 of its segment and f along it. prim: the
// BLAS triangle of the last hit the loop accepted (every accepted hit is nearer than the last).
template <bool AnyHit, BlasForm Form>
struct BlurredTlasFrame {
  const uint32_t* triIndex;  // the scene's (copied: no pointer to the kernel's parameter)
  const InstanceState* instances;
  const BlurredInstance* blurred;
  const BlasView* views;
  const BlurredLayout* layouts;
  const GpuBvhNode* nodes0;
  const GpuBvhNode* nodes1;
  const Aabb* boxes0;
  const Aabb* boxes1;
  const Affine3x4* toWorld0;
  const Affine3x4* toWorld1;
  float f, time;
  RootInfo root;
  mutable uint32_t prim = kNoHit;

  __device__ __forceinline__ BlurredTlasFrame(const BlurredTlasScene& s, float t)
      : triIndex(s.triIndex), instances(s.instances), blurred(s.blurred), views(s.views), layouts(s.layouts), time(t) {
    const motion::Segment seg = motion::segmentAt(s.keyTimes, int(s.keyCount), t);
    const std::size_t k = std::size_t(seg.index);
    nodes0 = s.keyNodes + k * s.nodeCount;
    nodes1 = nodes0 + s.nodeCount;
    boxes0 = s.keyBoxes + k * s.instanceCount;
    boxes1 = boxes0 + s.instanceCount;
    toWorld0 = s.keyToWorld + k * s.instanceCount;
    toWorld1 = toWorld0 + s.instanceCount;
    f = seg.f;
    root.box = motion::lerpBox(s.keyRootBoxes[k], s.keyRootBoxes[k + 1], f);
    root.ref = s.rootRef;
    root.count = s.rootCount;
  }
};

template <bool AnyHit, BlasForm Form>
__device__ __forceinline__ void loadBvh2Node(const BlurredTlasFrame<AnyHit, Form>& m, int32_t ref, float4& n0xy,
                                             float4& n1xy, float4& nz, int4& refs) {
  const GpuBvhNode node = lerpNode(m.nodes0[ref], m.nodes1[ref], m.f);
  const float4* rows = reinterpret_cast<const float4*>(&node);
  n0xy = rows[0], n1xy = rows[1], nz = rows[2];
  refs = *reinterpret_cast<const int4*>(rows + 3);
}

template <bool AnyHit, BlasForm Form>
__device__ __forceinline__ uint32_t slotTriangle(const BlurredTlasFrame<AnyHit, Form>& m, uint32_t s) {
  return __ldg(m.triIndex + s);
}

// Slot s's instance at the ray's time: its key boxes lerped first (as the CPU's blurred TLAS frame),
// then the ray in instance space (a moving instance: the lerped map inverted, none when singular;
// a still one: the instant inverse), then its BLAS at the ray's time.
template <bool AnyHit, BlasForm Form>
__device__ __forceinline__ bool intersectBvh2Slot(const BlurredTlasFrame<AnyHit, Form>& m, const Ray& ray,
                                                  const RayPrep& prep, uint32_t s, float tmax, float& t, float& u,
                                                  float& v) {
  const uint32_t instance = slotTriangle(m, s);
  const Aabb box = motion::lerpBox(m.boxes0[instance], m.boxes1[instance], m.f);
  float entry;
  if (!intersectBox(prep, box, ray.tmin, tmax, entry)) return false;
  const InstanceState& inst = m.instances[instance];
  const BlurredInstance blurred = m.blurred[instance];
  Affine3x4 space;
  if (blurred.moving) {
    if (!instanceSpaceOfRows(motion::lerpAffine(m.toWorld0[instance], m.toWorld1[instance], m.f), space))
      return false;  // flat at this time: never hit
  } else {
    if (!inst.visible) return false;
    space = inst.toInstance;
  }
  const Ray local = rayInInstance(space, ray, tmax);
  Hit h;
  if (blurred.layout != kInvalidIndex) {
    const BlurredLayout& layout = m.layouts[blurred.layout];
    if constexpr (AnyHit) {
      if (!bvh2BlurredAnyHit(layout, local, m.time)) return false;
    } else {
      h = bvh2BlurredClosestHit(layout, local, m.time);
    }
  } else {
    const BlasView& view = m.views[inst.view];
    if constexpr (AnyHit) {
      if (!blasAnyHit<Form>(view, local)) return false;
    } else {
      h = blasClosestHit<Form>(view, local);
    }
  }
  if constexpr (AnyHit) {
    t = tmax;  // the loop stops at the first accepted slot: no distance needed
    u = v = 0.0f;
    return true;
  } else {
    if (!h.valid() || !(h.t < tmax)) return false;
    t = h.t;
    u = h.u;
    v = h.v;
    m.prim = h.tri;
    return true;
  }
}

// The closest hit of a ray at shutter fraction `time` (instance kNoHit: none).
template <BlasForm Form>
__device__ __forceinline__ InstanceHit blurredTwoLevelClosestHit(const BlurredTlasScene& scene, const Ray& ray,
                                                                 float time) {
  BlurredTlasFrame<false, Form> frame(scene, time);
  Bvh2Stack stack;
  Bvh2Traversal<false> walk;
  walk.start(frame.root, ray, stack);
  walk.template run<false>(frame, stack);
  const Hit h = walk.closestHit(frame);
  return h.valid() ? InstanceHit{h.t, h.u, h.v, h.tri, frame.prim} : InstanceHit{0.0f, 0.0f, 0.0f, kNoHit, kNoHit};
}

// Whether anything is hit within (tmin, tmax) at shutter fraction `time`.
template <BlasForm Form>
__device__ __forceinline__ bool blurredTwoLevelAnyHit(const BlurredTlasScene& scene, const Ray& ray, float time) {
  BlurredTlasFrame<true, Form> frame(scene, time);
  Bvh2Stack stack;
  Bvh2Traversal<true> walk;
  walk.start(frame.root, ray, stack);
  walk.template run<false>(frame, stack);
  return walk.occluded();
}

}  // namespace tsah::cuda::detail
