// The GPU two-level runtime's blurred batch queries (two_level_blur.hpp): one thread per ray through
// two_level_blur_traversal.cuh. Compiled with -fmad=false (see CMakeLists.txt): the lerps, the
// inverse and the ray's move into instance space round as on the CPU.
#include "launch.hpp"
#include "ray_arrays.cuh"
#include "two_level_blur.hpp"
#include "two_level_blur_traversal.cuh"

namespace tsah::cuda::detail {

namespace {

__global__ void instanceRootBoxesKernel(const InstanceState* __restrict__ instances, const BlasView* __restrict__ views,
                                        uint32_t count, Aabb* __restrict__ boxes) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  boxes[i] = views[instances[i].view].root->box;
}

// Rays: const Ray* or ArrayRays; Times: const float* or ArrayTimes; Hits: InstanceHit* or
// ArrayInstanceHits (ray_arrays.cuh).
template <bool AnyHit, BlasForm Form, class Rays, class Times, class Hits>
__global__ void __launch_bounds__(128) blurredTwoLevelTraceKernel(BlurredTlasScene scene, Rays rays, Times times,
                                                                  uint32_t count, Hits hits,
                                                                  uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const Ray ray = loadRay(rays, i);
  if constexpr (AnyHit)
    occluded[i] = blurredTwoLevelAnyHit<Form>(scene, ray, loadTime(times, i)) ? 1 : 0;
  else
    storeInstanceHit(hits, i, blurredTwoLevelClosestHit<Form>(scene, ray, loadTime(times, i)));
}

template <BlasForm Form, class Rays, class Times, class Hits>
void launchBlurredTraceOfForm(const BlurredTlasScene& scene, const Rays& rays, const Times& times, uint32_t count,
                              const Hits& hits, uint8_t* occluded, cudaStream_t stream) {
  const unsigned block = 128;  // fixed by __launch_bounds__
  if (occluded)
    blurredTwoLevelTraceKernel<true, Form, Rays, Times, Hits>
        <<<gridFor(count, block), block, 0, stream>>>(scene, rays, times, count, hits, occluded);
  else
    blurredTwoLevelTraceKernel<false, Form, Rays, Times, Hits>
        <<<gridFor(count, block), block, 0, stream>>>(scene, rays, times, count, hits, occluded);
  CUDA_CHECK_LAUNCH("blurredTwoLevelTraceKernel");
}

template <class Rays, class Times, class Hits>
void launchBlurredTraceOf(const BlurredTlasScene& scene, const Rays& rays, const Times& times, uint32_t count,
                          const Hits& hits, uint8_t* occluded, cudaStream_t stream) {
  if (count == 0) return;
  if (scene.compressedBlas)
    launchBlurredTraceOfForm<BlasForm::Compressed>(scene, rays, times, count, hits, occluded, stream);
  else
    launchBlurredTraceOfForm<BlasForm::Binary>(scene, rays, times, count, hits, occluded, stream);
}

}  // namespace

void launchInstanceRootBoxes(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* boxes,
                             cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  instanceRootBoxesKernel<<<gridFor(count, block), block, 0, stream>>>(instances, views, count, boxes);
  CUDA_CHECK_LAUNCH("instanceRootBoxesKernel");
}

void launchBlurredTwoLevelTrace(const BlurredTlasScene& scene, const Ray* rays, const float* times, uint32_t count,
                                InstanceHit* hits, uint8_t* occluded, cudaStream_t stream) {
  launchBlurredTraceOf(scene, rays, times, count, hits, occluded, stream);
}

void launchBlurredTwoLevelArrayTrace(const BlurredTlasScene& scene, const ArrayRays& rays, const ArrayTimes& times,
                                     const ArrayInstanceHits& hits, uint8_t* occluded, cudaStream_t stream) {
  launchBlurredTraceOf(scene, rays, times, rays.count, hits, occluded, stream);
}

}  // namespace tsah::cuda::detail
