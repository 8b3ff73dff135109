// The blurred frame on the device: the build of its traversal layout from the key arrays, and the
// trace kernel over a ray buffer with one shutter fraction per ray: one thread per ray, the binary
// layout's device traversal (bvh2_traversal.cuh) over the two keys of the ray's segment, boxes and
// triangles lerped at the ray's time as the CPU runtime lerps them (tsah/layout/motion_blur.hpp).
#include "blurred_trace.hpp"
#include "bvh2_traversal.cuh"
#include "launch.hpp"

namespace tsah::cuda::detail {

namespace {

// Items, in a grid-stride loop: i < nodeCount * keyCount copies node n = i / keyCount of key
// k = i % keyCount (consecutive threads write consecutive records; the last key's node also to the
// instant nodes); then slot s's triangle at key k the same way; then, with keyRoots, the last key's
// positions one float each and the keys' root boxes. Each record is whole 16-byte rows.
__global__ void buildBlurredLayoutKernel(BlurredLayoutSources from, GpuBvhNode* __restrict__ nodes,
                                         KeyTriangle* __restrict__ triangles) {
  const uint32_t keys = from.keyCount, last = keys - 1;
  const uint64_t nodeItems = uint64_t(from.nodeCount) * keys, slotItems = uint64_t(from.slots) * keys;
  const uint64_t copyItems = from.keyRoots ? from.keyStride + keys : 0;
  const uint64_t items = nodeItems + slotItems + copyItems;
  const uint64_t stride = uint64_t(gridDim.x) * blockDim.x;
  for (uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < items; i += stride) {
    if (i < nodeItems) {
      const uint64_t n = i / keys, k = i % keys;
      const float4* src = reinterpret_cast<const float4*>(from.keyNodes + k * from.nodeCount + n);
      const float4 r0 = __ldg(src), r1 = __ldg(src + 1), r2 = __ldg(src + 2), r3 = __ldg(src + 3);
      float4* to = reinterpret_cast<float4*>(nodes + i);
      to[0] = r0, to[1] = r1, to[2] = r2, to[3] = r3;
      if (from.keyRoots && k == last) {
        float4* instant = reinterpret_cast<float4*>(from.lastNodes + n);
        instant[0] = r0, instant[1] = r1, instant[2] = r2, instant[3] = r3;
      }
    } else if (i < nodeItems + slotItems) {
      const uint64_t j = i - nodeItems, s = j / keys, k = j % keys;
      const float* p = from.keyPositions + k * from.keyStride;
      const uint32_t* ids = from.slotVertices + 3 * s;
      const uint64_t a = 3 * uint64_t(__ldg(ids)), b = 3 * uint64_t(__ldg(ids + 1)), c = 3 * uint64_t(__ldg(ids + 2));
      float4* to = reinterpret_cast<float4*>(triangles + j);
      to[0] = make_float4(__ldg(p + a), __ldg(p + a + 1), __ldg(p + a + 2), __ldg(p + b));
      to[1] = make_float4(__ldg(p + b + 1), __ldg(p + b + 2), __ldg(p + c), __ldg(p + c + 1));
      to[2] = make_float4(__ldg(p + c + 2), 0.0f, 0.0f, 0.0f);
    } else if (const uint64_t c = i - nodeItems - slotItems; c < from.keyStride) {
      from.lastPositions[c] = __ldg(from.keyPositions + last * from.keyStride + c);
    } else {
      const uint64_t k = c - from.keyStride;
      const Aabb box = from.keyRoots[k].box;
      from.keyRootBoxes[k] = box;
      if (k == last) from.lastRoot->box = box;
    }
  }
}

template <bool AnyHit>
__global__ void __launch_bounds__(128) blurredTraceKernel(BlurredLayout frame, const Ray* __restrict__ rays,
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

void launchBuildBlurredLayout(const BlurredLayoutSources& from, GpuBvhNode* nodes, KeyTriangle* triangles,
                              cudaStream_t stream) {
  const uint64_t items = (uint64_t(from.nodeCount) + from.slots) * from.keyCount +
                         (from.keyRoots ? from.keyStride + from.keyCount : 0);
  if (items == 0) return;
  const unsigned block = 256;
  buildBlurredLayoutKernel<<<gridFor(items, block), block, 0, stream>>>(from, nodes, triangles);
  CUDA_CHECK_LAUNCH("buildBlurredLayoutKernel");
}

void launchBlurredTrace(const BlurredLayout& frame, const Ray* rays, const float* times, uint32_t count, Hit* hits,
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
