// The trace kernel of the binary layout over a ray buffer: one thread per ray, or persistent warps
// that fetch rays from a global counter with dynamic fetch (Aila-Laine 2009/2012). The traversal
// itself is bvh2_traversal.cuh's.
#include "bvh2_traversal.cuh"
#include "cwbvh_kernels.hpp"
#include "kernels.hpp"
#include "launch.hpp"

namespace tsah::cuda::detail {

namespace {

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

// Persistent: resident warps take rays from *rayCounter as theirs finish (dynamic fetch);
// otherwise one thread per ray.
template <bool AnyHit, bool Persistent>
__global__ void __launch_bounds__(128) traceKernel(TraceScene scene, const Ray* __restrict__ rays, uint32_t rayCount,
                                                   Hit* __restrict__ hits, uint8_t* __restrict__ occluded,
                                                   uint32_t* __restrict__ rayCounter) {
  const RootInfo rootInfo = *scene.root;
  Bvh2Stack stack;
  Bvh2Traversal<AnyHit> walk;
  uint32_t rayIndex = 0;
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
      walk.start(rootInfo, loadRay(rays, rayIndex), stack);
      needRay = false;
    }
    walk.template run<Persistent>(scene, stack);
    if (walk.finished()) {
      if constexpr (AnyHit) {
        occluded[rayIndex] = walk.occluded() ? 1 : 0;
      } else {
        const Hit hit = walk.closestHit(scene);
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
