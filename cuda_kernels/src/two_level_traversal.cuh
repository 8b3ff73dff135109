#pragma once
// The trace of one ray through a two-level scene on the device, written once for the runtime's ray
// arrays (two_level_kernels.cu) and the renderer's fused passes (two_level_render.cu): the TLAS by
// the binary layout's device loop (bvh2_traversal.cuh) with a frame whose slot test is the
// instance (its world box first, as on the CPU), and at a TLAS leaf the ray moved into instance
// space (origin by the inverse, direction by its linear part, not normalized) traced through the
// instance's BLAS by the same loop, or by the compressed layout's traversal (cwbvh_layout.hpp).
// Compile the including file with -fmad=false: boxes and hits round as on the CPU.
#include "bvh2_traversal.cuh"
#include "tsah/core/instance_transform.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda::detail {

// The BLAS layout a trace is compiled for: every kernel that traces BLAS is compiled once per
// layout, launched by the runtime's (TlasScene::compressedBlas); one kernel holding both loops
// changed the binary kernels' register allocation (the renderer's primary pass spilled).
enum class BlasForm { Binary, Compressed };

// A ray in instance space through one BLAS view: the closest hit (tri: the triangle of the
// source), or whether anything is hit within the ray's interval. Inlined into the TLAS loop: a call
// (__noinline__, which spills nothing) measured slower than the inlined loop's spills.
template <BlasForm Form>
__device__ __forceinline__ Hit blasClosestHit(const BlasView& view, const Ray& local) {
  const RootInfo root = *view.root;
  if constexpr (Form == BlasForm::Compressed)
    return cwbvhClosestHit(blasCwbvhView(view, root), local);
  else
    return bvh2ClosestHit(blasTraceScene(view), root, local);
}

template <BlasForm Form>
__device__ __forceinline__ bool blasAnyHit(const BlasView& view, const Ray& local) {
  const RootInfo root = *view.root;
  if constexpr (Form == BlasForm::Compressed)
    return cwbvhAnyHit(blasCwbvhView(view, root), local);
  else
    return bvh2AnyHit(blasTraceScene(view), root, local);
}

// What the binary layout's device loop (bvh2_traversal.cuh) reads of the TLAS: its nodes as a
// flat tree's, and a slot's "triangle" is its instance's BLAS, traced with the ray in instance
// space. prim: the BLAS triangle of the last hit the loop accepted (the loop accepts every hit a
// slot test reports: it is nearer than the ray's current end).
template <bool AnyHit, BlasForm Form>
struct TlasLoopFrame {
  TlasScene scene;
  mutable uint32_t prim = kNoHit;
};

template <bool AnyHit, BlasForm Form>
__device__ __forceinline__ void loadBvh2Node(const TlasLoopFrame<AnyHit, Form>& f, int32_t ref, float4& n0xy,
                                             float4& n1xy, float4& nz, int4& refs) {
  const float4* n = reinterpret_cast<const float4*>(f.scene.nodes + ref);
  n0xy = __ldg(n), n1xy = __ldg(n + 1), nz = __ldg(n + 2);
  refs = __ldg(reinterpret_cast<const int4*>(n + 3));
}

template <bool AnyHit, BlasForm Form>
__device__ __forceinline__ uint32_t slotTriangle(const TlasLoopFrame<AnyHit, Form>& f, uint32_t s) {
  return __ldg(f.scene.triIndex + s);
}

// Slot s's instance: its BLAS (AnyHit: whether anything is hit before tmax).
template <bool AnyHit, BlasForm Form>
__device__ __forceinline__ bool intersectBvh2Slot(const TlasLoopFrame<AnyHit, Form>& f, const Ray& ray,
                                                  const RayPrep& prep, uint32_t s, float tmax, float& t, float& u,
                                                  float& v) {
  const uint32_t instance = slotTriangle(f, s);
  const InstanceState& inst = f.scene.instances[instance];
  // The instance's own box before its transform and BLAS (as the CPU runtime's TLAS frame).
  float entry;
  if (!inst.visible || !intersectBox(prep, f.scene.instanceBoxes[instance], ray.tmin, tmax, entry)) return false;
  const BlasView& view = f.scene.views[inst.view];
  const Ray local = rayInInstance(inst.toInstance, ray, tmax);
  if constexpr (AnyHit) {
    if (!blasAnyHit<Form>(view, local)) return false;
    t = tmax;
    u = v = 0.0f;
    return true;
  } else {
    const Hit h = blasClosestHit<Form>(view, local);
    if (!h.valid() || !(h.t < tmax)) return false;
    t = h.t;
    u = h.u;
    v = h.v;
    f.prim = h.tri;
    return true;
  }
}

// The closest hit of a world ray: instance, triangle of its source, t, u, v (instance kNoHit: none).
template <BlasForm Form>
__device__ __forceinline__ InstanceHit twoLevelClosestHit(const TlasScene& scene, const Ray& ray) {
  TlasLoopFrame<false, Form> frame;
  frame.scene = scene;
  Bvh2Stack stack;
  Bvh2Traversal<false> walk;
  walk.start(*scene.root, ray, stack);
  walk.run<false>(frame, stack);
  const Hit h = walk.closestHit(frame);
  return h.valid() ? InstanceHit{h.t, h.u, h.v, h.tri, frame.prim} : InstanceHit{0.0f, 0.0f, 0.0f, kNoHit, kNoHit};
}

// Whether anything is hit within the ray's interval.
template <BlasForm Form>
__device__ __forceinline__ bool twoLevelAnyHit(const TlasScene& scene, const Ray& ray) {
  TlasLoopFrame<true, Form> frame;
  frame.scene = scene;
  Bvh2Stack stack;
  Bvh2Traversal<true> walk;
  walk.start(*scene.root, ray, stack);
  walk.run<false>(frame, stack);
  return walk.occluded();
}

}  // namespace tsah::cuda::detail
