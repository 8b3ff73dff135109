// Ray traversal on the GPU: the Aila-Laine (2009/2012) while-while kernel with leaf postponing,
// persistent warps that fetch rays from a global counter, and dynamic fetch, written for Volta and
// later (independent thread scheduling): every warp-wide vote names its participants with
// __activemask(), no code assumes lock-step execution.
//
// The box test and the triangle test are the CPU runtime's own (ray.hpp, woop.hpp: the same
// arithmetic and the watertight fallback near edges), so hits agree with the CPU path.
#include "cwbvh_kernels.hpp"
#include "kernels.hpp"
#include "launch.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah::cuda::detail {

namespace {

constexpr int32_t kSentinel = 0x7fffffff;  // "stack empty": larger than any node index
// Below this many live lanes a warp leaves its traversal loop so that finished lanes fetch new rays.
constexpr int kDynamicFetchThreshold = 20;

__device__ __forceinline__ bool isInterior(int32_t ref) { return uint32_t(ref) < uint32_t(kSentinel); }

__device__ __forceinline__ Ray loadRay(const Ray* rays, uint32_t i) {
  const float4* p = reinterpret_cast<const float4*>(rays + i);
  const float4 a = __ldg(p), b = __ldg(p + 1);
  Ray r;
  r.org = {a.x, a.y, a.z};
  r.tmin = a.w;
  r.dir = {b.x, b.y, b.z};
  r.tmax = b.w;
  return r;
}

__device__ __forceinline__ WoopTriangle loadWoop(const WoopTriangle* woop, uint32_t s) {
  const float4* p = reinterpret_cast<const float4*>(woop + s);
  const float4 a = __ldg(p), b = __ldg(p + 1), c = __ldg(p + 2);
  return {{a.x, a.y, a.z, a.w}, {b.x, b.y, b.z, b.w}, {c.x, c.y, c.z, c.w}};
}

// intersectBox of ray.hpp on the node's packed child boxes: identical arithmetic.
__device__ __forceinline__ bool slab(const RayPrep& r, float loX, float hiX, float loY, float hiY, float loZ,
                                     float hiZ, float tmin, float tmax, float& tEntry) {
  const float x0 = (loX - r.org.x) * r.invDir.x, x1 = (hiX - r.org.x) * r.invDir.x;
  const float y0 = (loY - r.org.y) * r.invDir.y, y1 = (hiY - r.org.y) * r.invDir.y;
  const float z0 = (loZ - r.org.z) * r.invDir.z, z1 = (hiZ - r.org.z) * r.invDir.z;
  const float tn = fmaxf(fmaxf(fminf(x0, x1), fminf(y0, y1)), fmaxf(fminf(z0, z1), tmin));
  const float tf = fminf(fminf(fmaxf(x0, x1), fmaxf(y0, y1)), fminf(fmaxf(z0, z1), tmax)) * kSlabFarScale;
  tEntry = tn;
  return tn <= tf;
}

template <bool AnyHit, bool Persistent>
__global__ void __launch_bounds__(128) traceKernel(TraceScene scene, const Ray* __restrict__ rays, uint32_t rayCount,
                                                   Hit* __restrict__ hits, uint8_t* __restrict__ occluded,
                                                   uint32_t* __restrict__ rayCounter) {
  // Traversal stack in local memory: (reference, leaf count) of postponed far children.
  int2 stack[kTraversalStackSize + 1];
  stack[0] = make_int2(kSentinel, 0);

  const RootInfo rootInfo = *scene.root;

  Ray ray;
  RayPrep prep;
  Hit hit;
  float hitT = 0.0f;
  uint32_t rayIndex = 0;
  int sp = 0;
  int32_t nodeRef = kSentinel, leafRef = 0;
  uint32_t nodeCount = 0, leafCount = 0;
  bool needRay = true, fetchedOnce = false;

  for (;;) {
    if (needRay) {
      if constexpr (Persistent) {
        rayIndex = takeIndices(rayCounter);  // the lanes that need a ray right now
      } else {
        if (fetchedOnce) break;
        fetchedOnce = true;
        rayIndex = blockIdx.x * blockDim.x + threadIdx.x;
      }
      if (rayIndex >= rayCount) break;
      ray = loadRay(rays, rayIndex);
      prep = prepareRay(ray);
      hitT = ray.tmax;
      hit = Hit{};
      sp = 0;
      leafRef = 0;
      nodeRef = kSentinel;
      if (isLeafRef(rootInfo.ref)) {
        // A tree that is one leaf: the root box decides, as in the CPU traversal.
        float t;
        if (rootInfo.count > 0 && intersectBox(prep, rootInfo.box, ray.tmin, hitT, t)) {
          leafRef = rootInfo.ref;
          leafCount = rootInfo.count;
        }
      } else {
        nodeRef = rootInfo.ref;  // the children's boxes are tested there: the root box adds nothing
      }
      needRay = false;
    }

    while (nodeRef != kSentinel || leafRef < 0) {
      // Interior nodes until every live lane has found a leaf (or finished).
      while (isInterior(nodeRef)) {
        const float4* n = reinterpret_cast<const float4*>(scene.nodes + nodeRef);
        const float4 n0xy = __ldg(n), n1xy = __ldg(n + 1), nz = __ldg(n + 2);
        const int4 refs = __ldg(reinterpret_cast<const int4*>(n + 3));
        float t0, t1;
        const bool hit0 = slab(prep, n0xy.x, n0xy.y, n0xy.z, n0xy.w, nz.x, nz.y, ray.tmin, hitT, t0);
        const bool hit1 = slab(prep, n1xy.x, n1xy.y, n1xy.z, n1xy.w, nz.z, nz.w, ray.tmin, hitT, t1);
        if (!hit0 && !hit1) {
          const int2 top = stack[sp];
          sp -= sp > 0 ? 1 : 0;
          nodeRef = top.x;
          nodeCount = uint32_t(top.y);
        } else {
          const bool firstIs1 = !hit0 || (hit1 && t1 < t0);
          nodeRef = firstIs1 ? refs.y : refs.x;
          nodeCount = uint32_t(firstIs1 ? refs.w : refs.z);
          if (hit0 && hit1) {
            stack[++sp] = firstIs1 ? make_int2(refs.x, refs.z) : make_int2(refs.y, refs.w);
          }
        }
        // Postpone the first leaf found and keep descending.
        if (nodeRef < 0 && leafRef >= 0) {
          leafRef = nodeRef;
          leafCount = nodeCount;
          const int2 top = stack[sp];
          sp -= sp > 0 ? 1 : 0;
          nodeRef = top.x;
          nodeCount = uint32_t(top.y);
        }
        if (!__any_sync(__activemask(), leafRef >= 0)) break;
      }

      // Leaves: the postponed one, then the current reference while it is a leaf.
      while (leafRef < 0) {
        const uint32_t first = leafFirstSlot(leafRef);
        bool done = false;
        for (uint32_t s = first; s < first + leafCount; ++s) {
          const WoopTriangle w = loadWoop(scene.woop, s);
          auto fetch = [&](Vec3& v0, Vec3& v1, Vec3& v2) {
            const uint32_t* tri = scene.indices + 3 * std::size_t(__ldg(scene.triIndex + s));
            const float* p = scene.positions;
            const uint32_t a = __ldg(tri), b = __ldg(tri + 1), c = __ldg(tri + 2);
            v0 = {__ldg(p + 3 * a), __ldg(p + 3 * a + 1), __ldg(p + 3 * a + 2)};
            v1 = {__ldg(p + 3 * b), __ldg(p + 3 * b + 1), __ldg(p + 3 * b + 2)};
            v2 = {__ldg(p + 3 * c), __ldg(p + 3 * c + 1), __ldg(p + 3 * c + 2)};
          };
          float t, u, v;
          if (intersectTriangle(ray, prep, w, hitT, fetch, t, u, v)) {
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
          nodeRef = kSentinel;
          leafRef = 0;
          break;
        }
        leafRef = nodeRef;
        leafCount = nodeCount;
        if (nodeRef < 0) {
          const int2 top = stack[sp];
          sp -= sp > 0 ? 1 : 0;
          nodeRef = top.x;
          nodeCount = uint32_t(top.y);
        }
      }
      if constexpr (Persistent) {
        if (__popc(__activemask()) < kDynamicFetchThreshold) break;
      }
    }

    if (nodeRef == kSentinel && leafRef >= 0) {
      if constexpr (AnyHit) {
        occluded[rayIndex] = hit.valid() ? 1 : 0;
      } else {
        if (hit.valid()) hit.tri = __ldg(scene.triIndex + hit.tri);
        float4* out = reinterpret_cast<float4*>(hits + rayIndex);
        *out = make_float4(hit.t, hit.u, hit.v, __uint_as_float(hit.tri));
      }
      needRay = true;
    }
  }
}

template <bool AnyHit, bool Persistent>
void launchTyped(const TraceScene& scene, const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded,
                 uint32_t* rayCounter, const TraceLaunch& launch, cudaStream_t stream) {
  const unsigned block = 128;  // fixed by __launch_bounds__
  unsigned grid;
  if constexpr (Persistent) {
    grid = launch.blocks;
    if (grid == 0) {
      int device = 0, sms = 0;
      CUDA_CHECK(cudaGetDevice(&device));
      CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
      grid = unsigned(sms) * unsigned(traceBlocksPerMultiprocessor(AnyHit, block));
    }
    const unsigned needed = gridFor(count, block);
    if (grid > needed) grid = needed;
  } else {
    grid = gridFor(count, block);
  }
  traceKernel<AnyHit, Persistent><<<grid, block, 0, stream>>>(scene, rays, count, hits, occluded, rayCounter);
  CUDA_CHECK_LAUNCH(AnyHit ? "traceKernel<any hit>" : "traceKernel<closest hit>");
}

}  // namespace

int traceBlocksPerMultiprocessor(bool anyHit, uint32_t blockSize) {
  int blocks = 0;
  if (anyHit)
    CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, traceKernel<true, true>, int(blockSize), 0));
  else
    CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, traceKernel<false, true>, int(blockSize), 0));
  return blocks > 0 ? blocks : 1;
}

void launchTrace(const TraceScene& scene, const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded,
                 uint32_t* rayCounter, const TraceLaunch& launch, cudaStream_t stream) {
  if (count == 0) return;
  if (scene.cwbvhNodes) {  // the compressed wide layout (cwbvh.cu)
    launchCwbvhTrace(scene, rays, count, hits, occluded, rayCounter, launch, stream);
    return;
  }
  const bool anyHit = hits == nullptr;
  if (anyHit && launch.persistent)
    launchTyped<true, true>(scene, rays, count, hits, occluded, rayCounter, launch, stream);
  else if (anyHit)
    launchTyped<true, false>(scene, rays, count, hits, occluded, rayCounter, launch, stream);
  else if (launch.persistent)
    launchTyped<false, true>(scene, rays, count, hits, occluded, rayCounter, launch, stream);
  else
    launchTyped<false, false>(scene, rays, count, hits, occluded, rayCounter, launch, stream);
}

}  // namespace tsah::cuda::detail
