#pragma once
// The binary layout's traversal of one ray on the GPU: the Aila-Laine (2009/2012) while-while loop
// with leaf postponing, as a state (start, run, result) so that the trace kernel (traversal.cu: one
// thread per ray, or persistent warps that fetch rays as theirs finish) and the render's fused
// passes (render.cu: each thread makes its ray and traces it) share one copy. Written for Volta and
// later (independent thread scheduling): every warp-wide vote names its participants with
// __activemask(), no code assumes lock-step execution.
//
// The box test and the triangle test are the CPU runtime's own (ray.hpp, woop.hpp: the same
// arithmetic and the watertight fallback near edges), so hits agree with the CPU path.
#include "blurred_trace.hpp"
#include "device_types.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah::cuda::detail {

inline constexpr int32_t kBvh2StackEmpty = 0x7fffffff;  // "stack empty": larger than any node index
// Below this many live lanes a persistent warp leaves its traversal loop so that finished lanes
// fetch new rays (dynamic fetch).
inline constexpr int kDynamicFetchThreshold = 20;

__device__ __forceinline__ WoopTriangle loadWoop(const WoopTriangle* woop, uint32_t s) {
  const float4* p = reinterpret_cast<const float4*>(woop + s);
  const float4 a = __ldg(p), b = __ldg(p + 1), c = __ldg(p + 2);
  return {{a.x, a.y, a.z, a.w}, {b.x, b.y, b.z, b.w}, {c.x, c.y, c.z, c.w}};
}

// intersectBox of ray.hpp on the node's packed child boxes: identical arithmetic.
__device__ __forceinline__ bool bvh2Slab(const RayPrep& r, float loX, float hiX, float loY, float hiY, float loZ,
                                         float hiZ, float tmin, float tmax, float& tEntry) {
  const float x0 = (loX - r.org.x) * r.invDir.x, x1 = (hiX - r.org.x) * r.invDir.x;
  const float y0 = (loY - r.org.y) * r.invDir.y, y1 = (hiY - r.org.y) * r.invDir.y;
  const float z0 = (loZ - r.org.z) * r.invDir.z, z1 = (hiZ - r.org.z) * r.invDir.z;
  const float tn = fmaxf(fmaxf(fminf(x0, x1), fminf(y0, y1)), fmaxf(fminf(z0, z1), tmin));
  const float tf = fminf(fminf(fmaxf(x0, x1), fmaxf(y0, y1)), fminf(fmaxf(z0, z1), tmax)) * kSlabFarScale;
  tEntry = tn;
  return tn <= tf;
}

// What the loop reads of a frame, for the instant frame (TraceScene: packed nodes, Woop triangles)
// and a blurred one (BlurredFrame): a node's two child boxes as the packed rows n0xy, n1xy, nz
// (gpu_layout.hpp) with its references, a slot's triangle test, a slot's triangle id.
__device__ __forceinline__ void loadBvh2Node(const TraceScene& scene, int32_t ref, float4& n0xy, float4& n1xy,
                                             float4& nz, int4& refs) {
  const float4* n = reinterpret_cast<const float4*>(scene.nodes + ref);
  n0xy = __ldg(n), n1xy = __ldg(n + 1), nz = __ldg(n + 2);
  refs = __ldg(reinterpret_cast<const int4*>(n + 3));
}

__device__ __forceinline__ bool intersectBvh2Slot(const TraceScene& scene, const Ray& ray, const RayPrep& prep,
                                                  uint32_t s, float tmax, float& t, float& u, float& v) {
  const WoopTriangle w = loadWoop(scene.woop, s);
  auto fetch = [&](Vec3& v0, Vec3& v1, Vec3& v2) {
    const uint32_t* tri = scene.indices + 3 * std::size_t(__ldg(scene.triIndex + s));
    const float* p = scene.positions;
    const uint32_t a = __ldg(tri), b = __ldg(tri + 1), c = __ldg(tri + 2);
    v0 = {__ldg(p + 3 * a), __ldg(p + 3 * a + 1), __ldg(p + 3 * a + 2)};
    v1 = {__ldg(p + 3 * b), __ldg(p + 3 * b + 1), __ldg(p + 3 * b + 2)};
    v2 = {__ldg(p + 3 * c), __ldg(p + 3 * c + 1), __ldg(p + 3 * c + 2)};
  };
  return intersectTriangle(ray, prep, w, tmax, fetch, t, u, v);
}

__device__ __forceinline__ uint32_t slotTriangle(const TraceScene& scene, uint32_t s) {
  return __ldg(scene.triIndex + s);
}

// A blurred frame at one ray's time: the two keys of its segment in the blurred layout
// (blurred_trace.hpp), each node's and each slot's pair of keys one contiguous run of vector loads.
// Vertices are lerped as the CPU runtime's tsah::MotionFrame lerps them (motion::lerpVertex, the
// watertight test), so hits are the CPU runtime's; child boxes are the layout's pre-padded key-s
// boxes moved towards key s + 1 by their outward-rounded changes (blurred_node.hpp), which contain
// the same lerped triangles; only the loop is the one below. keyCount >= 2.
struct BlurredFrame {
  const float4* nodes;      // node 0's record of segment s; node n's at nodes + n * nodeStride
  const float4* triangles;  // key s of slot 0; slot t at triangles + t * triangleStride
  uint32_t nodeStride, triangleStride;  // in float4: 6 per segment, 3 per key
  const uint32_t* triIndex;
  float f;
  RootInfo root;

  __device__ __forceinline__ BlurredFrame(const BlurredLayout& l, float time) {
    const motion::Segment seg = motion::segmentAt(l.keyTimes, int(l.keyCount), time);
    const uint32_t k = uint32_t(seg.index);
    nodes = reinterpret_cast<const float4*>(l.nodes + k);
    triangles = reinterpret_cast<const float4*>(l.triangles + k);
    nodeStride = 6 * (l.keyCount - 1);
    triangleStride = 3 * l.keyCount;
    triIndex = l.triIndex;
    f = seg.f;
    root.box = motion::lerpBox(l.keyRootBoxes[k], l.keyRootBoxes[k + 1], f);
    root.ref = l.rootRef;
    root.count = l.rootCount;
  }
};

// A node's two child boxes at the ray's f from its record of the ray's segment
// (motion::BlurredNodeSegment, rows 0..5): key s's pre-padded rows, and (unless kKeysAlikeBit says
// every key holds the same boxes) each float moved by (f * scale) * delta, its binary16 change to
// key s + 1, in one fused multiply-add: 96 bytes read where two whole key records took 112. All six
// rows are loaded before the alike bit is looked at, as both keys of a slot are below: with rows 4
// and 5 (and a slot's second key) asked for only after the first rows came back, every moving
// node and triangle cost a second memory round trip, and the blurred frame took up to 7% longer on
// the eight data scenes (H100 and H200).
__device__ __forceinline__ float moved(float a, float fs, uint32_t halves, bool high) {
  return fmaf(fs, motion::halfValue(uint16_t(high ? halves >> 16 : halves & 0xffffu)), a);
}
__device__ __forceinline__ float4 movedRow(float4 a, float fs, uint32_t lowHalves, uint32_t highHalves) {
  return make_float4(moved(a.x, fs, lowHalves, false), moved(a.y, fs, lowHalves, true), moved(a.z, fs, highHalves, false),
                     moved(a.w, fs, highHalves, true));
}

__device__ __forceinline__ void loadBvh2Node(const BlurredFrame& m, int32_t ref, float4& n0xy, float4& n1xy,
                                             float4& nz, int4& refs) {
  const float4* p = m.nodes + std::size_t(ref) * m.nodeStride;
  n0xy = __ldg(p), n1xy = __ldg(p + 1), nz = __ldg(p + 2);
  refs = __ldg(reinterpret_cast<const int4*>(p + 3));
  const uint4 d = __ldg(reinterpret_cast<const uint4*>(p + 4));  // the changes of rows 0 and 1
  const uint4 tail = __ldg(reinterpret_cast<const uint4*>(p + 5));  // row 2's changes, the scale
  if (uint32_t(refs.z) & motion::kKeysAlikeBit) {
    refs.z = int32_t(uint32_t(refs.z) & ~motion::kKeysAlikeBit);
    return;
  }
  const float fs = m.f * __uint_as_float(tail.z);
  n0xy = movedRow(n0xy, fs, d.x, d.y);
  n1xy = movedRow(n1xy, fs, d.z, d.w);
  nz = movedRow(nz, fs, tail.x, tail.y);
}

// A slot's triangle at the ray's f: its vertices lerped between keys s and s + 1 (a still vertex
// with itself, as the CPU runtime lerps it), then the watertight test. Both keys are loaded at
// once: no second round trip for a moving triangle.
__device__ __forceinline__ bool intersectBvh2Slot(const BlurredFrame& m, const Ray& ray, const RayPrep& prep,
                                                  uint32_t s, float tmax, float& t, float& u, float& v) {
  const float4* p = m.triangles + std::size_t(s) * m.triangleStride;  // key s: rows 0..2, key s + 1: rows 3..5
  const float4 a0 = __ldg(p), a1 = __ldg(p + 1), a2 = __ldg(p + 2);
  const float4 b0 = __ldg(p + 3), b1 = __ldg(p + 4), b2 = __ldg(p + 5);
  const Vec3 v0 = motion::lerpVertex({a0.x, a0.y, a0.z}, {b0.x, b0.y, b0.z}, m.f);
  const Vec3 v1 = motion::lerpVertex({a0.w, a1.x, a1.y}, {b0.w, b1.x, b1.y}, m.f);
  const Vec3 v2 = motion::lerpVertex({a1.z, a1.w, a2.x}, {b1.z, b1.w, b2.x}, m.f);
  return intersectWatertight(prep, v0, v1, v2, ray.tmin, tmax, t, u, v);
}

__device__ __forceinline__ uint32_t slotTriangle(const BlurredFrame& m, uint32_t s) {
  return __ldg(m.triIndex + s);
}

// Postponed far children: (reference, leaf count); entry 0 is the "empty" sentinel. Kept outside
// Bvh2Traversal, in the caller's frame: with the array as a member the binary frames measured
// 20-45% longer on the BART scenes (H100, separate passes: Kitchen 2.97 against 2.34 ms, Robots
// 3.54 against 2.44); without it the kernel's registers and stack frame equal the hand-written loop's.
using Bvh2Stack = int2[kTraversalStackSize + 1];

template <bool AnyHit>
struct Bvh2Traversal {
  Ray ray;
  RayPrep prep;
  Hit hit;  // hit.tri: the slot until closestHit() looks the triangle up
  float hitT = 0.0f;
  int sp = 0;
  int32_t nodeRef = kBvh2StackEmpty, leafRef = 0;
  uint32_t nodeCount = 0, leafCount = 0;

  static __device__ __forceinline__ bool isInterior(int32_t ref) { return uint32_t(ref) < uint32_t(kBvh2StackEmpty); }

  // The root box first: a ray that misses the whole tree (most camera rays of a small character in
  // a wide frame) costs one box test and no node fetch. The root box contains every child box and
  // the box test is monotone, so no hit is lost.
  __device__ __forceinline__ void start(const RootInfo& root, const Ray& r, Bvh2Stack& stack) {
    ray = r;
    prep = prepareRay(ray);
    hitT = ray.tmax;
    hit = Hit{};
    stack[0] = make_int2(kBvh2StackEmpty, 0);
    sp = 0;
    leafRef = 0;
    nodeRef = kBvh2StackEmpty;
    float t;
    if (!intersectBox(prep, root.box, ray.tmin, hitT, t)) return;
    if (isLeafRef(root.ref)) {  // a tree that is one leaf
      if (root.count > 0) {
        leafRef = root.ref;
        leafCount = root.count;
      }
    } else {
      nodeRef = root.ref;
    }
  }

  __device__ __forceinline__ bool finished() const { return nodeRef == kBvh2StackEmpty && leafRef >= 0; }

  __device__ __forceinline__ void pop(const Bvh2Stack& stack) {
    const int2 top = stack[sp];
    sp -= sp > 0 ? 1 : 0;
    nodeRef = top.x;
    nodeCount = uint32_t(top.y);
  }

  // Traverses until the ray is finished or, with DynamicFetch, until fewer than
  // kDynamicFetchThreshold lanes of the warp are still in the loop (call again to go on).
  template <bool DynamicFetch, class Frame>
  __device__ __forceinline__ void run(const Frame& scene, Bvh2Stack& stack) {
    while (nodeRef != kBvh2StackEmpty || leafRef < 0) {
      // Interior nodes until every live lane has found a leaf (or finished).
      while (isInterior(nodeRef)) {
        float4 n0xy, n1xy, nz;
        int4 refs;
        loadBvh2Node(scene, nodeRef, n0xy, n1xy, nz, refs);
        float t0, t1;
        const bool hit0 = bvh2Slab(prep, n0xy.x, n0xy.y, n0xy.z, n0xy.w, nz.x, nz.y, ray.tmin, hitT, t0);
        const bool hit1 = bvh2Slab(prep, n1xy.x, n1xy.y, n1xy.z, n1xy.w, nz.z, nz.w, ray.tmin, hitT, t1);
        if (!hit0 && !hit1) {
          pop(stack);
        } else {
          const bool firstIs1 = !hit0 || (hit1 && t1 < t0);
          nodeRef = firstIs1 ? refs.y : refs.x;
          nodeCount = uint32_t(firstIs1 ? refs.w : refs.z);
          if (hit0 && hit1) stack[++sp] = firstIs1 ? make_int2(refs.x, refs.z) : make_int2(refs.y, refs.w);
        }
        // Postpone the first leaf found and keep descending.
        if (nodeRef < 0 && leafRef >= 0) {
          leafRef = nodeRef;
          leafCount = nodeCount;
          pop(stack);
        }
        if (!__any_sync(__activemask(), leafRef >= 0)) break;
      }

      // Leaves: the postponed one, then the current reference while it is a leaf.
      while (leafRef < 0) {
        const uint32_t first = leafFirstSlot(leafRef);
        bool done = false;
        for (uint32_t s = first; s < first + leafCount; ++s) {
          float t, u, v;
          if (intersectBvh2Slot(scene, ray, prep, s, hitT, t, u, v)) {
            hitT = t;
            hit.t = t;
            hit.u = u;
            hit.v = v;
            hit.tri = s;  // the slot for now; the triangle id is looked up once at the end
            if constexpr (AnyHit) {
              done = true;
              break;
            }
          }
        }
        if (done) {  // any hit: the ray is finished
          nodeRef = kBvh2StackEmpty;
          leafRef = 0;
          break;
        }
        leafRef = nodeRef;
        leafCount = nodeCount;
        if (nodeRef < 0) pop(stack);
      }
      if constexpr (DynamicFetch) {
        if (__popc(__activemask()) < kDynamicFetchThreshold) break;
      }
    }
  }

  // After the traversal: the closest hit with its triangle id, or whether anything was hit.
  template <class Frame>
  __device__ __forceinline__ Hit closestHit(const Frame& scene) const {
    Hit h = hit;
    if (h.valid()) h.tri = slotTriangle(scene, h.tri);
    return h;
  }
  __device__ __forceinline__ bool occluded() const { return hit.valid(); }
};

// One ray from start to end (the fused render passes).
__device__ __forceinline__ Hit bvh2ClosestHit(const TraceScene& scene, const RootInfo& root, const Ray& ray) {
  Bvh2Stack stack;
  Bvh2Traversal<false> walk;
  walk.start(root, ray, stack);
  walk.run<false>(scene, stack);
  return walk.closestHit(scene);
}

__device__ __forceinline__ bool bvh2AnyHit(const TraceScene& scene, const RootInfo& root, const Ray& ray) {
  Bvh2Stack stack;
  Bvh2Traversal<true> walk;
  walk.start(root, ray, stack);
  walk.run<false>(scene, stack);
  return walk.occluded();
}

// One ray of a blurred frame at its shutter fraction `time` (the blurred batch kernel, the render's
// blurred passes).
__device__ __forceinline__ Hit bvh2BlurredClosestHit(const BlurredLayout& layout, const Ray& ray, float time) {
  const BlurredFrame frame(layout, time);
  Bvh2Stack stack;
  Bvh2Traversal<false> walk;
  walk.start(frame.root, ray, stack);
  walk.run<false>(frame, stack);
  return walk.closestHit(frame);
}

__device__ __forceinline__ bool bvh2BlurredAnyHit(const BlurredLayout& layout, const Ray& ray, float time) {
  const BlurredFrame frame(layout, time);
  Bvh2Stack stack;
  Bvh2Traversal<true> walk;
  walk.start(frame.root, ray, stack);
  walk.run<false>(frame, stack);
  return walk.occluded();
}

// The part of a blurred frame that traces a ray at `time` (blurred_trace.hpp): `first` unless a
// later part starts at or before it.
__device__ __forceinline__ int laterPartAt(const BlurredShutter& s, float time) {
  if (s.laterCount == 0 || time < s.later[0].start) return -1;
  uint32_t p = 0;
  while (p + 1 < s.laterCount && s.later[p + 1].start <= time) ++p;
  return int(p);
}
__device__ __forceinline__ BlurredLayout layoutAt(const BlurredShutter& s, float time) {
  const int p = laterPartAt(s, time);
  return p < 0 ? s.first.layout : s.later[p].layout;
}
__device__ __forceinline__ MotionBvhView viewAt(const BlurredShutter& s, float time) {
  const int p = laterPartAt(s, time);
  return p < 0 ? s.first.view : s.later[p].view;
}
__device__ __forceinline__ Hit bvh2BlurredClosestHit(const BlurredShutter& s, const Ray& ray, float time) {
  return bvh2BlurredClosestHit(layoutAt(s, time), ray, time);
}
__device__ __forceinline__ bool bvh2BlurredAnyHit(const BlurredShutter& s, const Ray& ray, float time) {
  return bvh2BlurredAnyHit(layoutAt(s, time), ray, time);
}

}  // namespace tsah::cuda::detail
