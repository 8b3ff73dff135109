// The trace kernel of a blurred frame over a ray buffer with one shutter fraction per ray: one
// thread per ray, blurred_traversal.cuh's traversal.
#include "blurred_traversal.cuh"
#include "launch.hpp"

namespace tsah::cuda::detail {

namespace {

template <bool AnyHit>
__global__ void __launch_bounds__(128) blurredTraceKernel(BlurredScene scene, const Ray* __restrict__ rays,
                                                          const float* __restrict__ times, uint32_t count,
                                                          Hit* __restrict__ hits, uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const Hit h = blurredTrace<AnyHit>(scene, rays[i], times[i]);
  if constexpr (AnyHit)
    occluded[i] = h.valid() ? 1 : 0;
  else
    hits[i] = h;
}

}  // namespace

void launchBlurredTrace(const BlurredScene& scene, const Ray* rays, const float* times, uint32_t count, Hit* hits,
                        uint8_t* occluded, cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  if (occluded)
    blurredTraceKernel<true><<<gridFor(count, block), block, 0, stream>>>(scene, rays, times, count, hits, occluded);
  else
    blurredTraceKernel<false><<<gridFor(count, block), block, 0, stream>>>(scene, rays, times, count, hits, occluded);
  CUDA_CHECK_LAUNCH("blurredTraceKernel");
}

}  // namespace tsah::cuda::detail
