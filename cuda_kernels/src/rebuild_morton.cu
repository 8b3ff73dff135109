// The first step of both rebuilds: the primitives' boxes (computed from triangles, or given), the
// bounds of their centroids, 30-bit Morton codes over those bounds, and CUB's radix sort of the
// codes with the primitive ids. One kernel per step for both inputs (the box source is a template
// parameter), so a build over given boxes runs the triangle build's exact arithmetic.
#include <cub/device/device_radix_sort.cuh>

#include <algorithm>

#include "launch.hpp"
#include "rebuild_steps.cuh"
#include "triangle_boxes.cuh"

namespace tsah::cuda::detail {

namespace {

constexpr int kBoxBlock = 256;

// Where the box pass reads the primitives' boxes: computed from the triangles (and written to
// `out`, by triangle id, for the later steps), or given.
struct TriangleSource {
  const uint32_t* __restrict__ indices;
  const float* __restrict__ positions;
  Aabb* __restrict__ out;
  __device__ __forceinline__ Aabb operator()(uint32_t t) const {
    Aabb b;
    extendByTriangle(b, indices, positions, t);
    out[t] = b;
    return b;
  }
};
struct BoxSource {
  const Aabb* __restrict__ boxes;
  __device__ __forceinline__ Aabb operator()(uint32_t t) const { return loadBox(boxes, t); }
};

// The bounds of the primitives' centroids (and, from triangles, their boxes): each block reduces
// its share in registers and shared memory and adds one atomic per bound (few blocks, so the
// atomics do not serialize).
template <class Source>
__global__ void __launch_bounds__(kBoxBlock) centroidBoundsKernel(Source source, uint32_t n,
                                                                 int* __restrict__ centroidBounds) {
  // Centroid bounds as six minima: lo.xyz and -hi.xyz.
  float m[6] = {3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f};
  for (uint32_t t = blockIdx.x * blockDim.x + threadIdx.x; t < n; t += gridDim.x * blockDim.x) {
    const Vec3 c = source(t).center();
    m[0] = fminf(m[0], c.x), m[1] = fminf(m[1], c.y), m[2] = fminf(m[2], c.z);
    m[3] = fminf(m[3], -c.x), m[4] = fminf(m[4], -c.y), m[5] = fminf(m[5], -c.z);
  }
  __shared__ float partial[kBoxBlock / 32][6];
  const int lane = int(threadIdx.x & 31u), warp = int(threadIdx.x >> 5);
#pragma unroll
  for (int k = 0; k < 6; ++k) {
    m[k] = warpMin(m[k]);
    if (lane == 0) partial[warp][k] = m[k];
  }
  __syncthreads();
  if (threadIdx.x < 6) {
    float v = partial[0][threadIdx.x];
    for (int w = 1; w < kBoxBlock / 32; ++w) v = fminf(v, partial[w][threadIdx.x]);
    atomicMin(centroidBounds + threadIdx.x, orderedInt(v));
  }
}

__device__ __forceinline__ uint32_t quantize(float x, float lo, float scale) {
  const float q = (x - lo) * scale;
  return q <= 0.0f ? 0u : (q >= 1023.0f ? 1023u : uint32_t(q));
}

__global__ void mortonKernel(const Aabb* __restrict__ boxes, uint32_t n, const int* __restrict__ centroidBounds,
                             uint32_t* __restrict__ codes, uint32_t* __restrict__ ids) {
  const uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= n) return;
  const Vec3 lo{orderedFloat(centroidBounds[0]), orderedFloat(centroidBounds[1]), orderedFloat(centroidBounds[2])};
  const Vec3 hi{-orderedFloat(centroidBounds[3]), -orderedFloat(centroidBounds[4]), -orderedFloat(centroidBounds[5])};
  const Vec3 e = hi - lo;
  // 1024 cells per axis over the centroid bounds; a flat axis puts everything in cell 0.
  const Vec3 s{e.x > 0.0f ? 1024.0f / e.x : 0.0f, e.y > 0.0f ? 1024.0f / e.y : 0.0f, e.z > 0.0f ? 1024.0f / e.z : 0.0f};
  const Vec3 c = loadBox(boxes, t).center();
  codes[t] = (expandBits(quantize(c.x, lo.x, s.x)) << 2) | (expandBits(quantize(c.y, lo.y, s.y)) << 1) |
             expandBits(quantize(c.z, lo.z, s.z));
  ids[t] = t;
}

// The box pass over `source`, then the codes over the boxes it leaves in `boxes`.
template <class Source>
void launchBoxesAndCodes(Source source, const Aabb* boxes, uint32_t n, unsigned maxBoxBlocks, int32_t* centroidBounds,
                         uint32_t* codes, uint32_t* ids, cudaStream_t stream) {
  centroidBoundsKernel<<<std::min<unsigned>(gridFor(n, kBoxBlock), maxBoxBlocks), kBoxBlock, 0, stream>>>(
      source, n, centroidBounds);
  CUDA_CHECK_LAUNCH("centroidBoundsKernel");
  mortonKernel<<<gridFor(n, kRebuildBlock), kRebuildBlock, 0, stream>>>(boxes, n, centroidBounds, codes, ids);
  CUDA_CHECK_LAUNCH("mortonKernel");
}

}  // namespace

void launchMortonCodes(const uint32_t* indices, const float* positions, uint32_t n, unsigned maxBoxBlocks,
                       Aabb* triBox, int32_t* centroidBounds, uint32_t* codes, uint32_t* ids, cudaStream_t stream) {
  launchBoxesAndCodes(TriangleSource{indices, positions, triBox}, triBox, n, maxBoxBlocks, centroidBounds, codes, ids,
                      stream);
}

void launchMortonCodes(const Aabb* boxes, uint32_t n, unsigned maxBoxBlocks, int32_t* centroidBounds, uint32_t* codes,
                       uint32_t* ids, cudaStream_t stream) {
  launchBoxesAndCodes(BoxSource{boxes}, boxes, n, maxBoxBlocks, centroidBounds, codes, ids, stream);
}

void sortMortonCodes(void* temp, std::size_t& tempBytes, const uint32_t* codesIn, uint32_t* codesOut,
                     const uint32_t* idsIn, uint32_t* idsOut, uint32_t n, cudaStream_t stream) {
  CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp, tempBytes, codesIn, codesOut, idsIn, idsOut, int64_t(n), 0,
                                             kMortonBits, stream));
}

}  // namespace tsah::cuda::detail
