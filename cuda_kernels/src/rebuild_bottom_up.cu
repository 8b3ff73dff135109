// The last step of both rebuilds: boxes bottom-up with an atomic counter per node, the SAH leaf
// collapse decided on the way, and the GpuBvhNode of every interior node and the root written.
#include <cuda/atomic>

#include "launch.hpp"
#include "rebuild_steps.cuh"

namespace tsah::cuda::detail {

namespace {

// What the parent needs of a finished subtree: 3 x uint4 per node.
//   q0: lo.x lo.y lo.z hi.x   q1: hi.y hi.z cost count   q2: first ref interiorCount height
struct SubtreeInfo {
  Aabb box;
  float cost;
  uint32_t count;  // triangles
  uint32_t first;  // first slot
  int32_t ref;     // as the parent references it: a node, or a leaf of `count` triangles
  uint32_t interior;
  uint32_t height;
};

__device__ __forceinline__ void storeInfo(uint4* info, uint32_t node, const SubtreeInfo& s) {
  uint4* q = info + 3 * std::size_t(node);
  q[0] = make_uint4(__float_as_uint(s.box.lo.x), __float_as_uint(s.box.lo.y), __float_as_uint(s.box.lo.z),
                    __float_as_uint(s.box.hi.x));
  q[1] = make_uint4(__float_as_uint(s.box.hi.y), __float_as_uint(s.box.hi.z), __float_as_uint(s.cost), s.count);
  q[2] = make_uint4(s.first, uint32_t(s.ref), s.interior, s.height);
}

__device__ __forceinline__ SubtreeInfo loadInfo(const uint4* info, uint32_t node) {
  const uint4* q = info + 3 * std::size_t(node);
  const uint4 a = __ldcg(q), b = __ldcg(q + 1), c = __ldcg(q + 2);
  SubtreeInfo s;
  s.box.lo = {__uint_as_float(a.x), __uint_as_float(a.y), __uint_as_float(a.z)};
  s.box.hi = {__uint_as_float(a.w), __uint_as_float(b.x), __uint_as_float(b.y)};
  s.cost = __uint_as_float(b.z);
  s.count = b.w;
  s.first = c.x;
  s.ref = int32_t(c.y);
  s.interior = c.z;
  s.height = c.w;
  return s;
}

__device__ __forceinline__ SubtreeInfo childInfo(const BottomUpParams& p, int32_t ref) {
  if (!isLeafRef(ref)) return loadInfo(p.info, uint32_t(ref));
  SubtreeInfo s;  // a single triangle
  s.first = leafFirstSlot(ref);
  s.box = loadBox(p.primBox, __ldg(p.slotTri + s.first));
  s.count = 1;
  s.cost = p.ci * s.box.area();
  s.ref = ref;
  s.interior = 0;
  s.height = 0;
  return s;
}

template <bool Collapse>
__global__ void bottomUpKernel(BottomUpParams p) {
  const uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= p.n) return;
  uint32_t slot = __ldg(p.leafParent + s);
  if (slot == kNoParent) {  // one triangle, no interior node
    const SubtreeInfo leaf = childInfo(p, makeLeafRef(s));
    RootInfo r;
    r.box = leaf.box;
    r.ref = leaf.ref;
    r.count = 1;
    r.interiorCount = 0;
    r.depth = 0;
    *p.root = r;
    return;
  }
  for (;;) {
    const uint32_t node = slot >> 1;
    ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> arrivals(p.counters[node]);
    if (arrivals.fetch_add(1, ::cuda::memory_order_acq_rel) == 0) return;  // the sibling's thread goes on
    const int2 ch = p.children[node];
    const SubtreeInfo a = childInfo(p, ch.x), b = childInfo(p, ch.y);
    SubtreeInfo self;
    self.box = merge(a.box, b.box);
    self.count = a.count + b.count;
    self.first = min(a.first, b.first);
    const float area = self.box.area();
    const float keep = p.ct * area + a.cost + b.cost;
    const float asLeaf = p.ci * float(self.count) * area;
    const bool collapse = Collapse && self.count <= p.maxLeafSize && asLeaf <= keep;
    self.cost = collapse ? asLeaf : keep;
    self.ref = collapse ? makeLeafRef(self.first) : int32_t(node);
    self.interior = collapse ? 0u : 1u + a.interior + b.interior;
    self.height = collapse ? 0u : 1u + max(a.height, b.height);

    // The node as the traversal reads it (unreferenced when an ancestor collapses).
    float4* out = reinterpret_cast<float4*>(p.nodes + node);
    out[0] = make_float4(a.box.lo.x, a.box.hi.x, a.box.lo.y, a.box.hi.y);
    out[1] = make_float4(b.box.lo.x, b.box.hi.x, b.box.lo.y, b.box.hi.y);
    out[2] = make_float4(a.box.lo.z, a.box.hi.z, b.box.lo.z, b.box.hi.z);
    out[3] = make_float4(__int_as_float(a.ref), __int_as_float(b.ref),
                         __uint_as_float(isLeafRef(a.ref) ? a.count : 0u),
                         __uint_as_float(isLeafRef(b.ref) ? b.count : 0u));
    storeInfo(p.info, node, self);

    slot = p.nodeParent[node];
    if (slot == kNoParent) {
      RootInfo r;
      r.box = self.box;
      r.ref = self.ref;
      r.count = isLeafRef(self.ref) ? self.count : 0u;
      r.interiorCount = self.interior;
      r.depth = self.height;
      *p.root = r;
      return;
    }
  }
}

}  // namespace

void launchBottomUp(const BottomUpParams& p, bool collapse, cudaStream_t stream) {
  if (collapse)
    bottomUpKernel<true><<<gridFor(p.n, kRebuildBlock), kRebuildBlock, 0, stream>>>(p);
  else
    bottomUpKernel<false><<<gridFor(p.n, kRebuildBlock), kRebuildBlock, 0, stream>>>(p);
  CUDA_CHECK_LAUNCH("bottomUpKernel");
}

}  // namespace tsah::cuda::detail
