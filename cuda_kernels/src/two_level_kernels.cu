// The two-level runtime's kernels: instance world boxes, the TLAS refit over them, and the trace
// through instances with the CPU's traversal loop (tsah/layout/traversal.hpp) at both levels.
// Compiled with -fmad=false (see CMakeLists.txt): boxes and hits round as on the CPU.
#include <cuda/atomic>

#include "launch.hpp"
#include "tsah/layout/traversal.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda::detail {

namespace {

__global__ void instanceBoxesKernel(const InstanceState* __restrict__ instances, const BlasView* __restrict__ views,
                                    uint32_t count, Aabb* __restrict__ boxes) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const InstanceState& inst = instances[i];
  const Aabb box = views[inst.view].root->box;
  Aabb out;
  if (box.empty()) {
    boxes[i] = box;
    return;
  }
  // tsah::transformBox: the 8 corners in double, each rounded to float and widened by one ulp.
  const double* m = inst.world;
  for (int corner = 0; corner < 8; ++corner) {
    const double p[3] = {(corner & 1) ? box.hi.x : box.lo.x, (corner & 2) ? box.hi.y : box.lo.y,
                         (corner & 4) ? box.hi.z : box.lo.z};
    float q[3];
    for (int r = 0; r < 3; ++r)
      q[r] = float(m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3]);
    out.extend(Vec3{nextafterf(q[0], -3.4e38f), nextafterf(q[1], -3.4e38f), nextafterf(q[2], -3.4e38f)});
    out.extend(Vec3{nextafterf(q[0], 3.4e38f), nextafterf(q[1], 3.4e38f), nextafterf(q[2], 3.4e38f)});
  }
  boxes[i] = out;
}

// GpuBvhNode's child box layout (gpu_layout.hpp): child 0 x/y at floats 0..3, child 1 at 4..7, z at 8 / 10.
__device__ __forceinline__ void writeChildBox(GpuBvhNode* node, int side, const Aabb& b) {
  float* f = reinterpret_cast<float*>(node);
  const int xy = side == 0 ? 0 : 4, z = side == 0 ? 8 : 10;
  f[xy + 0] = b.lo.x;
  f[xy + 1] = b.hi.x;
  f[xy + 2] = b.lo.y;
  f[xy + 3] = b.hi.y;
  f[z + 0] = b.lo.z;
  f[z + 1] = b.hi.z;
}

__device__ __forceinline__ Aabb readChildBox(const GpuBvhNode* node, int side) {
  const float* f = reinterpret_cast<const float*>(node);  // written by another thread: through L2
  const int xy = side == 0 ? 0 : 4, z = side == 0 ? 8 : 10;
  Aabb b;
  b.lo = {__ldcg(f + xy + 0), __ldcg(f + xy + 2), __ldcg(f + z + 0)};
  b.hi = {__ldcg(f + xy + 1), __ldcg(f + xy + 3), __ldcg(f + z + 1)};
  return b;
}

// The flat runtime's refit walk (update_kernels.cu) with instance boxes as the leaves' content.
__global__ void tlasRefitKernel(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                                const LeafRecord* __restrict__ leaves, uint32_t leafCount,
                                const uint32_t* __restrict__ triIndex, const Aabb* __restrict__ instanceBoxes,
                                uint32_t* __restrict__ counters, RootInfo* __restrict__ root) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= leafCount) return;
  const LeafRecord leaf = leaves[i];
  Aabb box;
  for (uint32_t s = leaf.first; s < leaf.first + leaf.count; ++s) box.extend(instanceBoxes[triIndex[s]]);
  uint32_t slot = leaf.parentSlot;
  while (slot != kNoParent) {
    const uint32_t node = slot >> 1;
    const int side = int(slot & 1);
    writeChildBox(nodes + node, side, box);
    ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> arrivals(counters[node]);
    if (arrivals.fetch_add(1, ::cuda::memory_order_acq_rel) == 0) return;
    box.extend(readChildBox(nodes + node, 1 - side));
    slot = nodeParent[node];
  }
  root->box = box;
}

__device__ Vec3 transformPoint(const float* m, const Vec3& p) {
  return {m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
          m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]};
}
__device__ Vec3 transformVector(const float* m, const Vec3& d) {
  return {m[0] * d.x + m[1] * d.y + m[2] * d.z, m[4] * d.x + m[5] * d.y + m[6] * d.z,
          m[8] * d.x + m[9] * d.y + m[10] * d.z};
}

// What the shared traversal loop reads of the TLAS (the CPU's TlasFrame in two_level_runtime.cpp):
// a slot's "triangle" is its instance's BLAS, traced by the same loop with the ray in instance space.
template <bool AnyHit>
struct TlasFrame {
  TlasScene scene;
  int32_t rootRef = 0;
  uint32_t rootCount = 0;
  Aabb rootBox;
  const uint32_t* triIndex = nullptr;
  mutable uint32_t hitPrim = kNoHit;

  __device__ const Aabb& root() const { return rootBox; }
  __device__ const GpuBvhNode& node(int32_t ref) const { return scene.nodes[ref]; }
  __device__ bool intersectSlot(const Ray& ray, const RayPrep&, uint32_t s, float tmax, float& t, float& u,
                                float& v) const {
    const InstanceState& inst = scene.instances[triIndex[s]];
    if (!inst.visible) return false;
    const BlasView& view = scene.views[inst.view];
    BvhView blas;
    blas.nodes = view.nodes;
    blas.woop = view.woop;
    blas.triIndex = view.triIndex;
    blas.indices = view.indices;
    blas.positions = view.positions;
    blas.rootRef = view.root->ref;
    blas.rootCount = view.root->count;
    blas.rootBox = view.root->box;
    Ray local = ray;
    local.org = transformPoint(inst.toInstance, ray.org);
    local.dir = transformVector(inst.toInstance, ray.dir);
    local.tmax = tmax;
    if (AnyHit) {
      if (!anyHit(blas, local)) return false;
      t = tmax;
      u = v = 0.0f;
      return true;
    }
    const Hit h = closestHit(blas, local);
    if (!h.valid() || !(h.t < tmax)) return false;
    t = h.t;
    u = h.u;
    v = h.v;
    hitPrim = h.tri;
    return true;
  }
};

template <bool AnyHit>
__global__ void __launch_bounds__(128) twoLevelTraceKernel(TlasScene scene, const Ray* __restrict__ rays,
                                                           uint32_t count, InstanceHit* __restrict__ hits,
                                                           uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  TlasFrame<AnyHit> frame;
  frame.scene = scene;
  frame.rootRef = scene.root->ref;
  frame.rootCount = scene.root->count;
  frame.rootBox = scene.root->box;
  frame.triIndex = scene.triIndex;
  const Hit h = tsah::detail::traverse<AnyHit>(frame, rays[i]);
  if constexpr (AnyHit) {
    occluded[i] = h.valid() ? 1 : 0;
  } else {
    hits[i] = h.valid() ? InstanceHit{h.t, h.u, h.v, h.tri, frame.hitPrim} : InstanceHit{0.0f, 0.0f, 0.0f, kNoHit, kNoHit};
  }
}

}  // namespace

void launchInstanceBoxes(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* boxes,
                         cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  instanceBoxesKernel<<<gridFor(count, block), block, 0, stream>>>(instances, views, count, boxes);
  CUDA_CHECK_LAUNCH("instanceBoxesKernel");
}

void launchTlasRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                     const uint32_t* triIndex, const Aabb* instanceBoxes, uint32_t* counters, RootInfo* root,
                     cudaStream_t stream) {
  if (leafCount == 0) return;
  const unsigned block = 128;
  tlasRefitKernel<<<gridFor(leafCount, block), block, 0, stream>>>(nodes, nodeParent, leaves, leafCount, triIndex,
                                                                   instanceBoxes, counters, root);
  CUDA_CHECK_LAUNCH("tlasRefitKernel");
}

void launchTwoLevelTrace(const TlasScene& scene, const Ray* rays, uint32_t count, InstanceHit* hits, uint8_t* occluded,
                         cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  if (occluded)
    twoLevelTraceKernel<true><<<gridFor(count, block), block, 0, stream>>>(scene, rays, count, hits, occluded);
  else
    twoLevelTraceKernel<false><<<gridFor(count, block), block, 0, stream>>>(scene, rays, count, hits, occluded);
  CUDA_CHECK_LAUNCH("twoLevelTraceKernel");
}

}  // namespace tsah::cuda::detail
