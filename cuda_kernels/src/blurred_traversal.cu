// The trace kernel of a blurred frame over a ray buffer with one shutter fraction per ray: one
// thread per ray, the binary layout's device traversal (bvh2_traversal.cuh) over the two keys of
// the ray's segment, boxes and triangles lerped at the ray's time as the CPU runtime lerps them
// (tsah/layout/motion_blur.hpp).
#include "blurred_trace.hpp"
#include "bvh2_traversal.cuh"
#include "launch.hpp"

namespace tsah::cuda::detail {

namespace {

template <bool AnyHit>
__global__ void __launch_bounds__(128) blurredTraceKernel(MotionBvhView frame, const Ray* __restrict__ rays,
                                                          const float* __restrict__ times, uint32_t count,
                                                          Hit* __restrict__ hits, uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  if constexpr (AnyHit)
    occluded[i] = bvh2BlurredAnyHit(frame, rays[i], times[i]) ? 1 : 0;
  else
    hits[i] = bvh2BlurredClosestHit(frame, rays[i], times[i]);
}

}  // namespace

void launchBlurredTrace(const MotionBvhView& frame, const Ray* rays, const float* times, uint32_t count, Hit* hits,
                        uint8_t* occluded, cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  if (occluded)
    blurredTraceKernel<true><<<gridFor(count, block), block, 0, stream>>>(frame, rays, times, count, hits, occluded);
  else
    blurredTraceKernel<false><<<gridFor(count, block), block, 0, stream>>>(frame, rays, times, count, hits, occluded);
  CUDA_CHECK_LAUNCH("blurredTraceKernel");
}

}  // namespace tsah::cuda::detail
