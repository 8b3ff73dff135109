// The Karras (2012) radix tree over the sorted Morton codes: the LBVH's whole hierarchy, and the
// bottom levels below the clusters of HLBVH-SAH (which also takes each cluster's root from it).
#include "launch.hpp"
#include "rebuild_steps.cuh"

namespace tsah::cuda::detail {

namespace {

// Length of the common prefix of sorted keys i and j, the index breaking ties between equal keys;
// -1 outside the array.
__device__ __forceinline__ int delta(const uint32_t* __restrict__ keys, int64_t n, int64_t i, int64_t j) {
  if (j < 0 || j >= n) return -1;
  const uint32_t a = __ldg(keys + i), b = __ldg(keys + j);
  if (a == b) return 32 + __clz(uint32_t(i) ^ uint32_t(j));
  return __clz(a ^ b);
}

__global__ void karrasKernel(const uint32_t* __restrict__ keys, uint32_t n, KarrasOutput out) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const int64_t count = n;
  if (i >= count - 1) return;
  const int d = delta(keys, count, i, i + 1) - delta(keys, count, i, i - 1) >= 0 ? 1 : -1;
  const int deltaMin = delta(keys, count, i, i - d);
  int64_t lmax = 2;
  while (delta(keys, count, i, i + lmax * d) > deltaMin) lmax *= 2;
  int64_t l = 0;
  for (int64_t t = lmax / 2; t >= 1; t /= 2)
    if (delta(keys, count, i, i + (l + t) * d) > deltaMin) l += t;
  const int64_t j = i + l * d;
  const int deltaNode = delta(keys, count, i, j);
  int64_t s = 0;
  int64_t t = l;
  do {
    t = (t + 1) >> 1;
    if (delta(keys, count, i, i + (s + t) * d) > deltaNode) s += t;
  } while (t > 1);
  const int64_t gamma = i + s * d + (d < 0 ? -1 : 0);
  const int64_t first = d > 0 ? i : j, last = d > 0 ? j : i;
  const uint32_t self = uint32_t(i) << 1;
  int2 ch;
  if (first == gamma) {
    ch.x = makeLeafRef(uint32_t(gamma));
    out.leafParent[gamma] = self;
  } else {
    ch.x = int32_t(gamma);
    out.nodeParent[gamma] = self;
  }
  if (last == gamma + 1) {
    ch.y = makeLeafRef(uint32_t(gamma + 1));
    out.leafParent[gamma + 1] = self | 1u;
  } else {
    ch.y = int32_t(gamma + 1);
    out.nodeParent[gamma + 1] = self | 1u;
  }
  out.children[i] = ch;
  if (i == 0) out.nodeParent[0] = kNoParent;
  if (out.nodeRange) {
    out.nodeRange[i] = make_uint2(uint32_t(first), uint32_t(last));
    // The node whose range is exactly one cluster (a run of equal 15-bit prefixes) is its root.
    const uint32_t key = clusterKey(__ldg(keys + first));
    if (key == clusterKey(__ldg(keys + last)) && (first == 0 || clusterKey(__ldg(keys + first - 1)) != key) &&
        (last == count - 1 || clusterKey(__ldg(keys + last + 1)) != key))
      out.clusterRoot[out.clusterOf[first]] = int32_t(i);
  }
}

}  // namespace

void launchRadixTree(const uint32_t* keys, uint32_t n, const KarrasOutput& out, cudaStream_t stream) {
  karrasKernel<<<gridFor(n - 1, kRebuildBlock), kRebuildBlock, 0, stream>>>(keys, n, out);
  CUDA_CHECK_LAUNCH("karrasKernel");
}

}  // namespace tsah::cuda::detail
