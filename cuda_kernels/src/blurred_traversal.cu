// The blurred frame on the device: the build of its traversal layout from the key arrays, and the
// trace kernel over a ray buffer with one shutter fraction per ray: one thread per ray, the binary
// layout's device traversal (bvh2_traversal.cuh) over the two keys of the ray's segment, boxes and
// triangles lerped at the ray's time as the CPU runtime lerps them (tsah/layout/motion_blur.hpp).
#include "blurred_trace.hpp"
#include "bvh2_traversal.cuh"
#include "launch.hpp"

namespace tsah::cuda::detail {

namespace {

__device__ __forceinline__ bool sameBits(float4 a, float4 b) {
  return __float_as_uint(a.x) == __float_as_uint(b.x) && __float_as_uint(a.y) == __float_as_uint(b.y) &&
         __float_as_uint(a.z) == __float_as_uint(b.z) && __float_as_uint(a.w) == __float_as_uint(b.w);
}

__device__ __forceinline__ GpuBvhNode loadNodeRecord(const GpuBvhNode* at) {
  GpuBvhNode node;
  const float4* src = reinterpret_cast<const float4*>(at);
  float4* to = reinterpret_cast<float4*>(&node);
  to[0] = __ldg(src), to[1] = __ldg(src + 1), to[2] = __ldg(src + 2), to[3] = __ldg(src + 3);
  return node;
}

__device__ __forceinline__ void storeNodeRecord(GpuBvhNode* at, const GpuBvhNode& node) {
  const float4* from = reinterpret_cast<const float4*>(&node);
  float4* to = reinterpret_cast<float4*>(at);
  to[0] = from[0], to[1] = from[1], to[2] = from[2], to[3] = from[3];
}

// Whether two records' child boxes (rows 0..2) are the same bits.
__device__ __forceinline__ bool sameBoxes(const GpuBvhNode& a, const GpuBvhNode& b) {
  const float4* x = reinterpret_cast<const float4*>(&a);
  const float4* y = reinterpret_cast<const float4*>(&b);
  return sameBits(x[0], y[0]) && sameBits(x[1], y[1]) && sameBits(x[2], y[2]);
}

// Items, in a grid-stride loop: i < nodeCount writes node n = i's record of every segment
// (motion::encodeNodeSegment of its key records, child boxes pre-padded over all keys by
// motion::prepadBox, alike when they are the same at every key; the last key's record, unpadded,
// also to the instant nodes); then slot s's triangle at every key; then, with keyRoots, the last
// key's positions one float each and the keys' root boxes. Each record is whole 16-byte rows.
__global__ void buildBlurredLayoutKernel(BlurredLayoutSources from, motion::BlurredNodeSegment* __restrict__ nodes,
                                         KeyTriangle* __restrict__ triangles) {
  const uint32_t keys = from.keyCount, last = keys - 1;
  const uint64_t nodeItems = from.nodeCount, slotItems = from.slots;
  const uint64_t copyItems = from.keyRoots ? from.keyStride + keys : 0;
  const uint64_t items = nodeItems + slotItems + copyItems;
  const uint64_t stride = uint64_t(gridDim.x) * blockDim.x;
  for (uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < items; i += stride) {
    if (i < nodeItems) {
      const GpuBvhNode* key0 = from.keyNodes + i;  // key k at key0 + k * nodeCount
      const GpuBvhNode first = loadNodeRecord(key0);
      Vec3 m0{0.0f, 0.0f, 0.0f}, m1{0.0f, 0.0f, 0.0f};
      bool alike = true;
      for (uint32_t k = 0; k < keys; ++k) {
        const GpuBvhNode node = loadNodeRecord(key0 + uint64_t(k) * from.nodeCount);
        m0 = motion::foldMagnitudes(node.childBox(0), m0);
        m1 = motion::foldMagnitudes(node.childBox(1), m1);
        alike &= sameBoxes(first, node);
      }
      const auto prepadded = [&](uint32_t k) {
        GpuBvhNode node = loadNodeRecord(key0 + uint64_t(k) * from.nodeCount);
        node.setChildBox(0, motion::prepadBox(node.childBox(0), m0));
        node.setChildBox(1, motion::prepadBox(node.childBox(1), m1));
        return node;
      };
      GpuBvhNode atS = prepadded(0);
      for (uint32_t k = 0; k + 1 < keys; ++k) {
        const GpuBvhNode atNext = prepadded(k + 1);
        const motion::BlurredNodeSegment record = motion::encodeNodeSegment(atS, atNext, alike);
        const float4* row = reinterpret_cast<const float4*>(&record);
        float4* to = reinterpret_cast<float4*>(nodes + i * (keys - 1) + k);
        for (int r = 0; r < 6; ++r) to[r] = row[r];
        atS = atNext;
      }
      if (from.keyRoots) storeNodeRecord(from.lastNodes + i, loadNodeRecord(key0 + uint64_t(last) * from.nodeCount));
    } else if (i < nodeItems + slotItems) {
      const uint64_t s = i - nodeItems;
      const uint32_t* ids = from.slotVertices + 3 * s;
      const uint64_t a = 3 * uint64_t(__ldg(ids)), b = 3 * uint64_t(__ldg(ids + 1)), c = 3 * uint64_t(__ldg(ids + 2));
      for (uint32_t k = 0; k < keys; ++k) {
        const float* p = from.keyPositions + k * from.keyStride;
        const float4 r0 = make_float4(__ldg(p + a), __ldg(p + a + 1), __ldg(p + a + 2), __ldg(p + b));
        const float4 r1 = make_float4(__ldg(p + b + 1), __ldg(p + b + 2), __ldg(p + c), __ldg(p + c + 1));
        const float4 r2 = make_float4(__ldg(p + c + 2), 0.0f, 0.0f, 0.0f);
        float4* to = reinterpret_cast<float4*>(triangles + s * keys + k);
        to[0] = r0, to[1] = r1, to[2] = r2;
      }
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

// Parts: the frame has later parts; without, the first part's layout alone (no part lookup).
template <bool AnyHit, bool Parts>
__global__ void __launch_bounds__(128) blurredTraceKernel(BlurredShutter frame, const Ray* __restrict__ rays,
                                                          const float* __restrict__ times, uint32_t count,
                                                          Hit* __restrict__ hits, uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  if constexpr (AnyHit) {
    if constexpr (Parts)
      occluded[i] = bvh2BlurredAnyHit(frame, rays[i], times[i]) ? 1 : 0;
    else
      occluded[i] = bvh2BlurredAnyHit(frame.first.layout, rays[i], times[i]) ? 1 : 0;
  } else {
    if constexpr (Parts)
      hits[i] = bvh2BlurredClosestHit(frame, rays[i], times[i]);
    else
      hits[i] = bvh2BlurredClosestHit(frame.first.layout, rays[i], times[i]);
  }
}

template <bool AnyHit, bool Parts>
void launchBlurredTraceKernel(const BlurredShutter& frame, const Ray* rays, const float* times, uint32_t count,
                              Hit* hits, uint8_t* occluded, cudaStream_t stream) {
  const unsigned block = 128;
  blurredTraceKernel<AnyHit, Parts><<<gridFor(count, block), block, 0, stream>>>(frame, rays, times, count, hits,
                                                                                 occluded);
}

}  // namespace

void launchBuildBlurredLayout(const BlurredLayoutSources& from, motion::BlurredNodeSegment* nodes, KeyTriangle* triangles,
                              cudaStream_t stream) {
  const uint64_t items =
      uint64_t(from.nodeCount) + from.slots + (from.keyRoots ? from.keyStride + from.keyCount : 0);
  if (items == 0) return;
  const unsigned block = 256;
  buildBlurredLayoutKernel<<<gridFor(items, block), block, 0, stream>>>(from, nodes, triangles);
  CUDA_CHECK_LAUNCH("buildBlurredLayoutKernel");
}

void launchBlurredTrace(const BlurredShutter& frame, const Ray* rays, const float* times, uint32_t count, Hit* hits,
                        uint8_t* occluded, cudaStream_t stream) {
  if (count == 0) return;
  const bool parts = frame.laterCount > 0;
  if (occluded)
    parts ? launchBlurredTraceKernel<true, true>(frame, rays, times, count, hits, occluded, stream)
          : launchBlurredTraceKernel<true, false>(frame, rays, times, count, hits, occluded, stream);
  else
    parts ? launchBlurredTraceKernel<false, true>(frame, rays, times, count, hits, occluded, stream)
          : launchBlurredTraceKernel<false, false>(frame, rays, times, count, hits, occluded, stream);
  CUDA_CHECK_LAUNCH("blurredTraceKernel");
}

}  // namespace tsah::cuda::detail
