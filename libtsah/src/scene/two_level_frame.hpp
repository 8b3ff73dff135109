#pragma once
// What the shared traversal loop (detail::traverse) reads of a two-level runtime's binary TLAS, for
// the instant frame (two_level_runtime.cpp) and a blurred one at one ray's time
// (two_level_motion.cpp): its nodes, and as the "triangle" of a slot the instance's BLAS, traced with
// the ray moved into instance space; and the same instance step as the wide TLAS's visitor.
#include <optional>
#include <type_traits>

#include "tsah/core/instance_transform.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/layout/wide_visit.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/scene/two_level_runtime.hpp"

namespace tsah::detail {

// World -> instance space of a float instance -> world map (instanceSpaceOfRows: the inverse in
// double, rounded to float, as the GPU runtime computes it; none when singular).
inline std::optional<Affine3x4> instanceSpaceOf(const Affine3x4& toWorld) {
  Affine3x4 space;
  if (!instanceSpaceOfRows(toWorld, space)) return std::nullopt;
  return space;
}

// An instance's BLAS traced with the ray moved into its space (`space`: world -> instance), in
// (ray.tmin, tmax): true when hit; closest hit: t, u, v and the BLAS triangle `prim` of the hit,
// nearer than tmax. Any hit: the BLAS's `order`. Blurred: at the ray's shutter fraction `time`.
template <bool AnyHit, bool Blurred>
inline bool traceInstance(const CpuRuntime& blas, const Affine3x4& space, const Ray& ray, float tmax, float time,
                          AnyHitOrder order, float& t, float& u, float& v, uint32_t& prim) {
  const Ray local = rayInInstanceHost(space, ray, tmax);
  if constexpr (AnyHit) {  // the caller stops at the first hit: no distance needed
    return Blurred ? blas.anyHit(local, time, order) : blas.anyHit(local, order);
  } else {
    const Hit h = Blurred ? blas.closestHit(local, time) : blas.closestHit(local);
    if (!h.valid() || !(h.t < tmax)) return false;
    t = h.t;
    u = h.u;
    v = h.v;
    prim = h.tri;
    return true;
  }
}

// The instant frame's instances as the wide TLAS's items (wide_visit.hpp, wide_tlas.hpp): the
// instance's box was tested by the kernel's node test; a singular instance is skipped, the others
// traced by traceInstance. hitPrim holds the BLAS triangle of the last accepted visit, the final
// hit (every accepted visit shortens tmax). Lives for one ray.
template <bool AnyHit>
struct InstanceVisit {
  const Affine3x4* toInstance = nullptr;
  const uint8_t* visible = nullptr;
  const CpuRuntime* const* blas = nullptr;
  AnyHitOrder order = AnyHitOrder::FarthestFirst;
  mutable uint32_t hitPrim = kNoHit;

  static bool visit(const void* context, uint32_t instance, const Ray& ray, float& tmax, Hit& hit) {
    const InstanceVisit& c = *static_cast<const InstanceVisit*>(context);
    if (!c.visible[instance]) return false;
    float t = tmax, u = 0.0f, v = 0.0f;
    uint32_t prim = kNoHit;
    if (!traceInstance<AnyHit, false>(*c.blas[instance], c.toInstance[instance], ray, tmax, 0.0f, c.order, t, u, v, prim))
      return false;
    tmax = t;
    hit = {t, u, v, instance};
    c.hitPrim = prim;
    return true;
  }
  WideLeafVisitor visitor() const { return {this, &InstanceVisit::visit}; }
};

// The blurred TLAS at one ray's time: the keys s and s + 1 of its segment and f along it.
struct TlasKeys {
  const GpuBvhNode* nodes0 = nullptr;  // the TLAS's interior nodes at key s and s + 1
  const GpuBvhNode* nodes1 = nullptr;
  const Aabb* boxes0 = nullptr;  // per instance: its box at key s and s + 1
  const Aabb* boxes1 = nullptr;
  const Affine3x4* toWorld0 = nullptr;  // per instance: instance -> world at key s and s + 1
  const Affine3x4* toWorld1 = nullptr;
  const uint8_t* moving = nullptr;  // per instance: its matrix differs between keys
  Aabb root;  // the TLAS's root box at f
  float f = 0.0f;
  float time = 0.0f;  // the ray's shutter fraction: the BLAS runtimes find their own segment
};

// The frame lives for one ray: hitPrim holds the BLAS triangle of the last accepted slot test,
// which is the final hit (every accepted test shortens tmax, so the last one is the nearest).
// Blurred: nodes and instance boxes lerped at the ray's time, a moving instance's matrix lerped
// and inverted per test, the BLAS traced at the ray's time.
template <bool AnyHit, bool Blurred>
struct TlasFrame {
  const GpuBvhNode* nodes = nullptr;
  const uint32_t* triIndex = nullptr;  // slot -> instance id
  const Affine3x4* toInstance = nullptr;
  const Aabb* instanceBoxes = nullptr;      // per instance: its world box this frame
  const uint8_t* visible = nullptr;         // per instance: 0 while its world transform is singular
  const CpuRuntime* const* blas = nullptr;  // per instance, traced in its own layout
  int32_t rootRef = makeLeafRef(0);
  uint32_t rootCount = 0;
  Aabb rootBox;
  AnyHitOrder order = AnyHitOrder::FarthestFirst;  // any hit: the BLAS traversals' child order
  TlasKeys keys;                                   // Blurred only
  mutable uint32_t hitPrim = kNoHit;

  const Aabb& root() const { return rootBox; }
  std::conditional_t<Blurred, GpuBvhNode, const GpuBvhNode&> node(int32_t ref) const {
    if constexpr (Blurred)
      return lerpNode(keys.nodes0[ref], keys.nodes1[ref], keys.f);
    else
      return nodes[ref];
  }
  bool intersectSlot(const Ray& ray, const RayPrep& prep, uint32_t s, float tmax, float& t, float& u, float& v) const {
    const uint32_t instance = triIndex[s];
    // The instance's own box before its transform and BLAS: a leaf of several instances is entered
    // by rays that miss most of them (the test is the TLAS nodes' own, on a box inside theirs).
    float entry;
    Affine3x4 space;
    if constexpr (Blurred) {
      const Aabb box = motion::lerpBox(keys.boxes0[instance], keys.boxes1[instance], keys.f);
      if (!intersectBox(prep, box, ray.tmin, tmax, entry)) return false;
      if (keys.moving[instance]) {
        const std::optional<Affine3x4> at =
            instanceSpaceOf(motion::lerpAffine(keys.toWorld0[instance], keys.toWorld1[instance], keys.f));
        if (!at) return false;  // flat at this time: never hit
        space = *at;
      } else {
        if (!visible[instance]) return false;
        space = toInstance[instance];
      }
    } else {
      if (!visible[instance] || !intersectBox(prep, instanceBoxes[instance], ray.tmin, tmax, entry)) return false;
      space = toInstance[instance];
    }
    t = tmax;  // any hit: the loop stops at the first accepted slot, no distance needed
    u = v = 0.0f;
    return traceInstance<AnyHit, Blurred>(*blas[instance], space, ray, tmax, keys.time, order, t, u, v, hitPrim);
  }
};

template <bool AnyHit, bool Blurred>
TlasFrame<AnyHit, Blurred> tlasFrame(const FlatBvh& tlas, const std::vector<Affine3x4>& toInstance,
                                     const std::vector<Aabb>& instanceBoxes, const std::vector<uint8_t>& visible,
                                     const std::vector<const CpuRuntime*>& blas) {
  TlasFrame<AnyHit, Blurred> f;
  f.nodes = tlas.nodes.data();
  f.triIndex = tlas.triIndex.data();
  f.toInstance = toInstance.data();
  f.instanceBoxes = instanceBoxes.data();
  f.blas = blas.data();
  f.visible = visible.data();
  f.rootRef = tlas.rootRef;
  f.rootCount = tlas.rootCount;
  f.rootBox = tlas.rootBoxes[0];
  return f;
}

// The traversal's hit as a two-level hit: the slot's instance and the frame's BLAS triangle.
template <class Frame>
TwoLevelHit twoLevelHit(const Hit& h, const Frame& frame) {
  TwoLevelHit hit;
  if (!h.valid()) return hit;
  hit.t = h.t;
  hit.u = h.u;
  hit.v = h.v;
  hit.instance = h.tri;
  hit.prim = frame.hitPrim;
  return hit;
}

}  // namespace tsah::detail
