// The per-frame GPU rebuild baselines: LBVH (Karras 2012) and HLBVH-SAH (Garanzha et al. 2011),
// both followed by the SAH leaf collapse and the Woop triangles. See rebuild.hpp for the outline.
#include <cub/block/block_scan.cuh>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda/atomic>

#include <algorithm>
#include <string>

#include "kernels.hpp"
#include "triangle_boxes.cuh"
#include "launch.hpp"
#include "rebuild.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah::cuda::detail {

namespace {

constexpr int kMortonBits = 30;         // 10 per axis
constexpr int kClusterShift = 15;       // HLBVH-SAH clusters: the top 15 of the 30 bits (5 per axis)
constexpr uint32_t kMaxClusters = 1u << 15;
constexpr int kTopBlock = 128;          // threads of a block of the cluster-tree builder
constexpr int kTopBins = 32;            // grid cells per axis at the cluster level (5 bits)

// Floats as ints whose signed order is the float order, so atomicMin works on floats.
__device__ __forceinline__ int orderedInt(float f) {
  const int i = __float_as_int(f);
  return i >= 0 ? i : i ^ 0x7fffffff;
}
__device__ __forceinline__ float orderedFloat(int i) { return __int_as_float(i >= 0 ? i : i ^ 0x7fffffff); }

// 0x7f7f7f7f (what cudaMemset(0x7f) writes) as an ordered int is a huge positive float: the
// starting value of a minimum.
constexpr int kOrderedHuge = 0x7f7f7f7f;

__device__ __forceinline__ Aabb loadBox(const Aabb* boxes, uint32_t i) {
  const float* f = reinterpret_cast<const float*>(boxes + i);
  Aabb b;
  b.lo = {__ldg(f), __ldg(f + 1), __ldg(f + 2)};
  b.hi = {__ldg(f + 3), __ldg(f + 4), __ldg(f + 5)};
  return b;
}

__device__ __forceinline__ float warpMin(float v) {
  for (int o = 16; o > 0; o >>= 1) v = fminf(v, __shfl_xor_sync(0xffffffffu, v, o));
  return v;
}

// --- Morton codes ------------------------------------------------------------------------------

constexpr int kBoxBlock = 256;

// Triangle boxes, and the bounds of their centroids: each block reduces its share in registers and
// shared memory and adds one atomic per bound (few blocks, so the atomics do not serialize).
__global__ void __launch_bounds__(kBoxBlock) triangleBoxesKernel(const uint32_t* __restrict__ indices,
                                                                const float* __restrict__ positions, uint32_t n,
                                                                Aabb* __restrict__ triBox,
                                                                int* __restrict__ centroidBounds) {
  // Centroid bounds as six minima: lo.xyz and -hi.xyz.
  float m[6] = {3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f};
  for (uint32_t t = blockIdx.x * blockDim.x + threadIdx.x; t < n; t += gridDim.x * blockDim.x) {
    Aabb b;
    extendByTriangle(b, indices, positions, t);
    triBox[t] = b;
    const Vec3 c = b.center();
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

// 10 bits spread to every third bit.
__device__ __forceinline__ uint32_t expandBits(uint32_t v) {
  v = (v * 0x00010001u) & 0xFF0000FFu;
  v = (v * 0x00000101u) & 0x0F00F00Fu;
  v = (v * 0x00000011u) & 0xC30C30C3u;
  v = (v * 0x00000005u) & 0x49249249u;
  return v;
}
__device__ __forceinline__ uint32_t compactBits(uint32_t v) {
  v &= 0x49249249u;
  v = (v ^ (v >> 2)) & 0xC30C30C3u;
  v = (v ^ (v >> 4)) & 0x0F00F00Fu;
  v = (v ^ (v >> 8)) & 0xFF0000FFu;
  v = (v ^ (v >> 16)) & 0x000003FFu;
  return v;
}

__device__ __forceinline__ uint32_t quantize(float x, float lo, float scale) {
  const float q = (x - lo) * scale;
  return q <= 0.0f ? 0u : (q >= 1023.0f ? 1023u : uint32_t(q));
}

__global__ void mortonKernel(const Aabb* __restrict__ triBox, uint32_t n, const int* __restrict__ centroidBounds,
                             uint32_t* __restrict__ codes, uint32_t* __restrict__ ids) {
  const uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= n) return;
  const Vec3 lo{orderedFloat(centroidBounds[0]), orderedFloat(centroidBounds[1]), orderedFloat(centroidBounds[2])};
  const Vec3 hi{-orderedFloat(centroidBounds[3]), -orderedFloat(centroidBounds[4]), -orderedFloat(centroidBounds[5])};
  const Vec3 e = hi - lo;
  // 1024 cells per axis over the centroid bounds; a flat axis puts everything in cell 0.
  const Vec3 s{e.x > 0.0f ? 1024.0f / e.x : 0.0f, e.y > 0.0f ? 1024.0f / e.y : 0.0f, e.z > 0.0f ? 1024.0f / e.z : 0.0f};
  const Vec3 c = loadBox(triBox, t).center();
  codes[t] = (expandBits(quantize(c.x, lo.x, s.x)) << 2) | (expandBits(quantize(c.y, lo.y, s.y)) << 1) |
             expandBits(quantize(c.z, lo.z, s.z));
  ids[t] = t;
}

// --- Karras radix tree -------------------------------------------------------------------------

// Length of the common prefix of sorted keys i and j, the index breaking ties between equal keys;
// -1 outside the array.
__device__ __forceinline__ int delta(const uint32_t* __restrict__ keys, int64_t n, int64_t i, int64_t j) {
  if (j < 0 || j >= n) return -1;
  const uint32_t a = __ldg(keys + i), b = __ldg(keys + j);
  if (a == b) return 32 + __clz(uint32_t(i) ^ uint32_t(j));
  return __clz(a ^ b);
}

__device__ __forceinline__ uint32_t clusterKey(uint32_t code) { return code >> kClusterShift; }

struct KarrasOutput {
  int2* children;
  uint32_t* nodeParent;
  uint32_t* leafParent;
  // HLBVH-SAH only (null for LBVH):
  uint2* nodeRange;
  const uint32_t* clusterOf;
  int32_t* clusterRoot;
};

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

// --- HLBVH-SAH clusters ------------------------------------------------------------------------

// Cluster words: clusterCount, queue head, queue tail.
enum QueueWord { kClusterCount = 0, kQueueHead = 1, kQueueTail = 2, kTasksDone = 3, kQueueWords = 4 };

__global__ void clusterHeadsKernel(const uint32_t* __restrict__ keys, uint32_t n, uint32_t* __restrict__ heads) {
  const uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  // 1 where a new cluster starts (never at 0), so the inclusive sum is the cluster index.
  heads[s] = s > 0 && clusterKey(__ldg(keys + s)) != clusterKey(__ldg(keys + s - 1)) ? 1u : 0u;
}

struct ClusterSetup {
  uint32_t* clusterBegin;
  uint32_t* clusterEnd;
  uint32_t* clusterCell;
  int32_t* clusterRoot;
  uint32_t* clusterParent;
  uint32_t* orderA;
  uint32_t* finalOrder;
  uint4* tasks;
  uint32_t* taskReady;
  uint32_t* words;
};

__global__ void clusterSetupKernel(const uint32_t* __restrict__ keys, uint32_t n, const uint32_t* __restrict__ clusterOf,
                                   ClusterSetup out) {
  const uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  const uint32_t c = clusterOf[s];
  const uint32_t key = clusterKey(__ldg(keys + s));
  const bool head = s == 0 || clusterKey(__ldg(keys + s - 1)) != key;
  const bool tail = s == n - 1 || clusterKey(__ldg(keys + s + 1)) != key;
  if (head) {
    out.clusterBegin[c] = s;
    // The 15-bit prefix interleaves 5 bits per axis: x at bit 2 of each triple, then y, z.
    out.clusterCell[c] = compactBits(key >> 2) | (compactBits(key >> 1) << 5) | (compactBits(key) << 10);
    out.clusterParent[c] = kNoParent;
    out.orderA[c] = c;
    out.finalOrder[c] = c;
  }
  if (tail) out.clusterEnd[c] = s + 1;
  if (head && tail) out.clusterRoot[c] = makeLeafRef(s);  // one triangle: the cluster is a leaf
  if (s == n - 1) {
    const uint32_t clusters = c + 1;
    out.words[kClusterCount] = clusters;
    out.words[kQueueHead] = 0;
    out.words[kQueueTail] = clusters >= 2 ? 1u : 0u;
    out.words[kTasksDone] = 0;
    if (clusters >= 2) {  // the root task: every cluster, read from orderA
      out.tasks[0] = make_uint4(0u, clusters, kNoParent, 0u);
      out.taskReady[0] = 1u;  // the builder starts after this kernel: no ordering needed
    }
  }
}

// One warp per cluster: the union of its triangle boxes.
__global__ void clusterBoxKernel(const uint32_t* __restrict__ sortedIds, const Aabb* __restrict__ triBox,
                                 const uint32_t* __restrict__ clusterBegin, const uint32_t* __restrict__ clusterEnd,
                                 const uint32_t* __restrict__ words, Aabb* __restrict__ clusterBox) {
  const uint32_t clusters = words[kClusterCount];
  const uint32_t lane = threadIdx.x & 31u;
  const uint32_t warps = (gridDim.x * blockDim.x) >> 5;
  for (uint32_t c = (blockIdx.x * blockDim.x + threadIdx.x) >> 5; c < clusters; c += warps) {
    const uint32_t end = clusterEnd[c];
    float m[6] = {3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f};
    for (uint32_t s = clusterBegin[c] + lane; s < end; s += 32) {
      const Aabb b = loadBox(triBox, __ldg(sortedIds + s));
      m[0] = fminf(m[0], b.lo.x), m[1] = fminf(m[1], b.lo.y), m[2] = fminf(m[2], b.lo.z);
      m[3] = fminf(m[3], -b.hi.x), m[4] = fminf(m[4], -b.hi.y), m[5] = fminf(m[5], -b.hi.z);
    }
#pragma unroll
    for (int k = 0; k < 6; ++k) m[k] = warpMin(m[k]);
    if (lane == 0) {
      Aabb b;
      b.lo = {m[0], m[1], m[2]};
      b.hi = {-m[3], -m[4], -m[5]};
      clusterBox[c] = b;
    }
  }
}

struct TopParams {
  const uint32_t* clusterBegin;
  const uint32_t* clusterEnd;
  const uint32_t* clusterCell;
  const Aabb* clusterBox;
  const int32_t* clusterRoot;
  uint32_t* orderA;
  uint32_t* orderB;
  uint32_t* finalOrder;
  uint32_t* clusterParent;
  int2* children;
  uint32_t* nodeParent;
  uint32_t nodeBase;  // index of cluster-tree node 0 (n - 1)
  uint4* tasks;       // (begin, end, parent slot, which order buffer holds the range)
  uint32_t* taskReady;
  uint32_t* words;
};

__device__ __forceinline__ uint32_t cellAxis(uint32_t cell, int axis) { return (cell >> (5 * axis)) & 31u; }

__device__ __forceinline__ float boxArea(float lx, float ly, float lz, float hx, float hy, float hz) {
  if (lx > hx || ly > hy || lz > hz) return 0.0f;
  const float dx = hx - lx, dy = hy - ly, dz = hz - lz;
  return 2.0f * (dx * dy + dy * dz + dz * dx);
}

// The SAH tree over the clusters, top-down, by persistent blocks. A block splits a node and goes
// on with one child itself (the larger; work first, so the deepest chain of splits runs without
// hand-offs) and pushes the other onto a queue that idle blocks take from in order. A block waiting
// for a queue slot is either served by a block that is running (it holds an earlier slot or a
// local child) or released when every node is done, so the waits always end, resident or not.
// A node with m clusters is split on the 32^3 grid of the cluster prefixes: the bins are the 32
// cells of each axis (empty bins only repeat a neighbour's split), the best bin boundary by the
// SAH (triangle counts times areas) wins, and the clusters are partitioned stably. A node is named
// by its split position (begin + left count - 1), which is unique, so the tree is the same
// whichever block builds what.
__global__ void __launch_bounds__(kTopBlock) clusterTreeKernel(TopParams p) {
  using BlockScan = cub::BlockScan<uint32_t, kTopBlock>;
  __shared__ typename BlockScan::TempStorage scanStorage;
  __shared__ uint32_t binTris[3][kTopBins], binClusters[3][kTopBins];
  __shared__ int binBox[3][kTopBins][6];  // ordered ints: min lo.xyz, min -hi.xyz
  __shared__ float bestCost[3];
  __shared__ int bestBin[3];
  __shared__ uint32_t bestLeft[3];
  __shared__ uint4 task;          // (begin, end, parent slot, which order buffer holds the range)
  __shared__ bool haveTask;
  __shared__ uint32_t single[2];  // the cluster of a side that holds only one

  const uint32_t clusters = p.words[kClusterCount];
  if (clusters < 2) return;
  const uint32_t taskCount = clusters - 1;  // interior nodes of a binary tree over the clusters
  const int tid = int(threadIdx.x), lane = tid & 31, warp = tid >> 5;
  bool keepLocal = false;  // thread 0's: `task` already holds the next node (a child of the last)

  for (;;) {
    if (tid == 0 && !keepLocal) {
      // Take the next queue slot; wait for its node, or stop once every node is done.
      haveTask = false;
      const uint32_t idx = atomicAdd(p.words + kQueueHead, 1u);
      if (idx < taskCount) {
        ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> ready(p.taskReady[idx]);
        ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> done(p.words[kTasksDone]);
        for (uint32_t spins = 0;; ++spins) {
          if (ready.load(::cuda::memory_order_acquire) != 0) {
            task = __ldcg(p.tasks + idx);
            haveTask = true;
            break;
          }
          if (done.load(::cuda::memory_order_acquire) == taskCount) break;
          if (spins == (1u << 30)) __trap();  // a bug, not a wait: fail the launch instead of hanging
          __nanosleep(64);
        }
      }
    }
    for (int k = tid; k < 3 * kTopBins; k += kTopBlock) {
      (&binTris[0][0])[k] = 0;
      (&binClusters[0][0])[k] = 0;
      for (int c = 0; c < 6; ++c) (&binBox[0][0][0])[k * 6 + c] = kOrderedHuge;
    }
    __syncthreads();
    if (!haveTask) return;
    const uint32_t begin = task.x, end = task.y, parentSlot = task.z, parity = task.w;
    const uint32_t* src = parity ? p.orderB : p.orderA;
    uint32_t* dst = parity ? p.orderA : p.orderB;

    // Bins: triangle and cluster counts, boxes. The first cluster of each thread stays in registers
    // for the partition (nodes of up to kTopBlock clusters are read once).
    uint32_t firstCluster = 0, firstCell = 0;
    for (uint32_t q = begin + tid; q < end; q += kTopBlock) {
      const uint32_t c = __ldcg(src + q);
      const uint32_t cell = __ldg(p.clusterCell + c);
      if (q < begin + kTopBlock) {
        firstCluster = c;
        firstCell = cell;
      }
      const uint32_t tris = __ldg(p.clusterEnd + c) - __ldg(p.clusterBegin + c);
      const Aabb b = loadBox(p.clusterBox, c);
      const int v[6] = {orderedInt(b.lo.x), orderedInt(b.lo.y), orderedInt(b.lo.z),
                        orderedInt(-b.hi.x), orderedInt(-b.hi.y), orderedInt(-b.hi.z)};
      for (int a = 0; a < 3; ++a) {
        const uint32_t bin = cellAxis(cell, a);
        atomicAdd(&binTris[a][bin], tris);
        atomicAdd(&binClusters[a][bin], 1u);
        for (int k = 0; k < 6; ++k) atomicMin(&binBox[a][bin][k], v[k]);
      }
    }
    __syncthreads();

    // One warp per axis, one lane per bin: prefix (left) and suffix (right) sums and boxes.
    if (warp < 3) {
      const int a = warp;
      float L[6], R[6];
      uint32_t lt = binTris[a][lane], lc = binClusters[a][lane];
      for (int k = 0; k < 6; ++k) L[k] = orderedFloat(binBox[a][lane][k]);
      uint32_t rt = lt;
      for (int k = 0; k < 6; ++k) R[k] = L[k];
      for (int o = 1; o < 32; o <<= 1) {
        const uint32_t t1 = __shfl_up_sync(0xffffffffu, lt, o), c1 = __shfl_up_sync(0xffffffffu, lc, o);
        const uint32_t t2 = __shfl_down_sync(0xffffffffu, rt, o);
        float l1[6], r1[6];
        for (int k = 0; k < 6; ++k) {
          l1[k] = __shfl_up_sync(0xffffffffu, L[k], o);
          r1[k] = __shfl_down_sync(0xffffffffu, R[k], o);
        }
        if (lane >= o) {
          lt += t1;
          lc += c1;
          for (int k = 0; k < 6; ++k) L[k] = fminf(L[k], l1[k]);
        }
        if (lane + o < 32) {
          rt += t2;
          for (int k = 0; k < 6; ++k) R[k] = fminf(R[k], r1[k]);
        }
      }
      // Split between bin `lane` and bin `lane + 1`: the right side is the suffix from lane + 1.
      const uint32_t rightTris = __shfl_down_sync(0xffffffffu, rt, 1);
      float r[6];
      for (int k = 0; k < 6; ++k) r[k] = __shfl_down_sync(0xffffffffu, R[k], 1);
      float cost = 3.0e38f;
      if (lane + 1 < kTopBins && lt > 0 && rightTris > 0)
        cost = boxArea(L[0], L[1], L[2], -L[3], -L[4], -L[5]) * float(lt) +
               boxArea(r[0], r[1], r[2], -r[3], -r[4], -r[5]) * float(rightTris);
      // Lowest cost, then lowest bin.
      float best = cost;
      int bestLane = lane;
      for (int o = 16; o > 0; o >>= 1) {
        const float c2 = __shfl_xor_sync(0xffffffffu, best, o);
        const int l2 = __shfl_xor_sync(0xffffffffu, bestLane, o);
        if (c2 < best || (c2 == best && l2 < bestLane)) {
          best = c2;
          bestLane = l2;
        }
      }
      const uint32_t leftClusters = __shfl_sync(0xffffffffu, lc, bestLane);
      if (lane == 0) {
        bestCost[a] = best;
        bestBin[a] = bestLane;
        bestLeft[a] = leftClusters;
      }
    }
    __syncthreads();
    // Distinct clusters differ in some cell coordinate, so some axis always has a valid split.
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (bestCost[a] < bestCost[axis]) axis = a;
    const int splitBin = bestBin[axis];
    const uint32_t leftCount = bestLeft[axis];
    const uint32_t rightCount = end - begin - leftCount;

    // Stable partition of the node's clusters into the other order buffer.
    uint32_t leftSoFar = 0;
    for (uint32_t chunk = begin; chunk < end; chunk += kTopBlock) {
      const uint32_t q = chunk + uint32_t(tid);
      const bool valid = q < end;
      uint32_t c = 0, cell = 0;
      if (valid) {
        const bool cached = chunk == begin;
        c = cached ? firstCluster : __ldcg(src + q);
        cell = cached ? firstCell : __ldg(p.clusterCell + c);
      }
      const uint32_t isLeft = valid && int(cellAxis(cell, axis)) <= splitBin ? 1u : 0u;
      uint32_t before, total;
      BlockScan(scanStorage).ExclusiveSum(isLeft, before, total);
      if (valid) {
        const uint32_t leftIndex = leftSoFar + before;
        const uint32_t at = isLeft ? begin + leftIndex : begin + leftCount + (q - begin - leftIndex);
        dst[at] = c;
        if (isLeft && leftCount == 1) single[0] = c;
        if (!isLeft && rightCount == 1) single[1] = c;
      }
      leftSoFar += total;
      __syncthreads();  // scanStorage is reused
    }
    __threadfence();  // the partition must be visible to the blocks that take the children
    __syncthreads();

    if (tid == 0) {
      const uint32_t node = p.nodeBase + begin + leftCount - 1;
      p.nodeParent[node] = parentSlot;
      if (parentSlot != kNoParent)
        reinterpret_cast<int32_t*>(p.children + (parentSlot >> 1))[parentSlot & 1] = int32_t(node);
      const uint32_t ranges[2][2] = {{begin, begin + leftCount}, {begin + leftCount, end}};
      const uint32_t counts[2] = {leftCount, rightCount};
      // The larger child stays with this block, the other goes to the queue.
      const int local = counts[1] > counts[0] ? 1 : 0;
      keepLocal = false;
      for (int side = 0; side < 2; ++side) {
        const uint32_t slot = (node << 1) | uint32_t(side);
        if (counts[side] == 1) {
          const uint32_t c = single[side];
          p.finalOrder[ranges[side][0]] = c;
          p.clusterParent[c] = slot;
          reinterpret_cast<int32_t*>(p.children + node)[side] = __ldg(p.clusterRoot + c);
        } else if (side == local) {
          task = make_uint4(ranges[side][0], ranges[side][1], slot, 1u - parity);
          keepLocal = true;
        } else {
          const uint32_t at = atomicAdd(p.words + kQueueTail, 1u);
          p.tasks[at] = make_uint4(ranges[side][0], ranges[side][1], slot, 1u - parity);
          ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> ready(p.taskReady[at]);
          ready.store(1u, ::cuda::memory_order_release);
        }
      }
      ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> done(p.words[kTasksDone]);
      done.fetch_add(1u, ::cuda::memory_order_release);
      haveTask = keepLocal;
    }
    __syncthreads();  // `task`, the bins and haveTask are overwritten by the next round
  }
}

// New first slot of every cluster: the clusters in the cluster tree's leaf order, sizes summed.
// One block; clusters <= 2^15 = 1024 threads x 32.
constexpr int kOrderBlock = 1024;
constexpr int kOrderItems = int(kMaxClusters) / kOrderBlock;

__global__ void __launch_bounds__(kOrderBlock) clusterSlotsKernel(const uint32_t* __restrict__ finalOrder,
                                                                 const uint32_t* __restrict__ clusterBegin,
                                                                 const uint32_t* __restrict__ clusterEnd,
                                                                 const uint32_t* __restrict__ words,
                                                                 uint32_t* __restrict__ newBegin) {
  using BlockScan = cub::BlockScan<uint32_t, kOrderBlock>;
  __shared__ typename BlockScan::TempStorage storage;
  const uint32_t clusters = words[kClusterCount];
  const uint32_t first = threadIdx.x * kOrderItems;
  uint32_t sizes[kOrderItems];
  uint32_t sum = 0;
#pragma unroll
  for (int k = 0; k < kOrderItems; ++k) {
    const uint32_t q = first + uint32_t(k);
    uint32_t size = 0;
    if (q < clusters) {
      const uint32_t c = finalOrder[q];
      size = clusterEnd[c] - clusterBegin[c];
    }
    sizes[k] = size;
    sum += size;
  }
  uint32_t offset;
  BlockScan(storage).ExclusiveSum(sum, offset);
#pragma unroll
  for (int k = 0; k < kOrderItems; ++k) {
    const uint32_t q = first + uint32_t(k);
    if (q < clusters) newBegin[finalOrder[q]] = offset;
    offset += sizes[k];
  }
}

// Triangles to their final slots: clusters in the cluster tree's order, radix order inside.
__global__ void permuteKernel(uint32_t n, const uint32_t* __restrict__ clusterOf, const uint32_t* __restrict__ clusterBegin,
                              const uint32_t* __restrict__ clusterEnd, const uint32_t* __restrict__ newBegin,
                              const uint32_t* __restrict__ clusterParent, const uint32_t* __restrict__ sortedIds,
                              const uint32_t* __restrict__ leafParentRadix, uint32_t* __restrict__ slotTri,
                              uint32_t* __restrict__ slotMap, uint32_t* __restrict__ leafParent) {
  const uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  const uint32_t c = clusterOf[s];
  const uint32_t b = clusterBegin[c];
  const uint32_t to = newBegin[c] + (s - b);
  slotTri[to] = sortedIds[s];
  slotMap[s] = to;
  leafParent[to] = clusterEnd[c] - b == 1 ? clusterParent[c] : leafParentRadix[s];
}

// Leaf references to the new slots; the cluster roots hang below the cluster tree.
__global__ void remapKernel(uint32_t n, const uint32_t* __restrict__ keys, const uint2* __restrict__ nodeRange,
                            const uint32_t* __restrict__ clusterOf, const int32_t* __restrict__ clusterRoot,
                            const uint32_t* __restrict__ clusterParent, const uint32_t* __restrict__ words,
                            const uint32_t* __restrict__ slotMap, int2* __restrict__ children,
                            uint32_t* __restrict__ nodeParent) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  const uint32_t radixNodes = n - 1;
  const uint32_t clusters = words[kClusterCount];
  if (i >= radixNodes + clusters - 1) return;
  if (i < radixNodes) {
    const uint2 range = nodeRange[i];
    if (clusterKey(keys[range.x]) != clusterKey(keys[range.y])) return;  // above the clusters: replaced
    const uint32_t c = clusterOf[range.x];
    if (clusterRoot[c] == int32_t(i)) nodeParent[i] = clusterParent[c];
  }
  int2 ch = children[i];
  if (isLeafRef(ch.x)) ch.x = makeLeafRef(slotMap[leafFirstSlot(ch.x)]);
  if (isLeafRef(ch.y)) ch.y = makeLeafRef(slotMap[leafFirstSlot(ch.y)]);
  children[i] = ch;
}

// --- Bottom-up boxes, leaf collapse, node output -----------------------------------------------

// What the parent needs of a finished subtree: 3 x uint4 per node.
//   q0: lo.x lo.y lo.z hi.x   q1: hi.y hi.z cost count   q2: first ref interiorCount height
struct SubtreeInfo {
  Aabb box;
  float cost;
  uint32_t count;  // triangles
  uint32_t first;  // first slot
  int32_t ref;     // as the parent references it: a node, or a leaf of `count` triangles
  uint32_t interior;
  uint32_t height;
};

__device__ __forceinline__ void storeInfo(uint4* info, uint32_t node, const SubtreeInfo& s) {
  uint4* q = info + 3 * std::size_t(node);
  q[0] = make_uint4(__float_as_uint(s.box.lo.x), __float_as_uint(s.box.lo.y), __float_as_uint(s.box.lo.z),
                    __float_as_uint(s.box.hi.x));
  q[1] = make_uint4(__float_as_uint(s.box.hi.y), __float_as_uint(s.box.hi.z), __float_as_uint(s.cost), s.count);
  q[2] = make_uint4(s.first, uint32_t(s.ref), s.interior, s.height);
}

__device__ __forceinline__ SubtreeInfo loadInfo(const uint4* info, uint32_t node) {
  const uint4* q = info + 3 * std::size_t(node);
  const uint4 a = __ldcg(q), b = __ldcg(q + 1), c = __ldcg(q + 2);
  SubtreeInfo s;
  s.box.lo = {__uint_as_float(a.x), __uint_as_float(a.y), __uint_as_float(a.z)};
  s.box.hi = {__uint_as_float(a.w), __uint_as_float(b.x), __uint_as_float(b.y)};
  s.cost = __uint_as_float(b.z);
  s.count = b.w;
  s.first = c.x;
  s.ref = int32_t(c.y);
  s.interior = c.z;
  s.height = c.w;
  return s;
}

struct BottomUpParams {
  uint32_t n;
  const uint32_t* slotTri;
  const uint32_t* leafParent;
  const Aabb* triBox;
  const int2* children;
  const uint32_t* nodeParent;
  uint32_t* counters;
  uint4* info;
  GpuBvhNode* nodes;
  RootInfo* root;
  float ct, ci;
  uint32_t maxLeafSize;
};

__device__ __forceinline__ SubtreeInfo childInfo(const BottomUpParams& p, int32_t ref) {
  if (!isLeafRef(ref)) return loadInfo(p.info, uint32_t(ref));
  SubtreeInfo s;  // a single triangle
  s.first = leafFirstSlot(ref);
  s.box = loadBox(p.triBox, __ldg(p.slotTri + s.first));
  s.count = 1;
  s.cost = p.ci * s.box.area();
  s.ref = ref;
  s.interior = 0;
  s.height = 0;
  return s;
}

template <bool Collapse>
__global__ void bottomUpKernel(BottomUpParams p) {
  const uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= p.n) return;
  uint32_t slot = __ldg(p.leafParent + s);
  if (slot == kNoParent) {  // one triangle, no interior node
    const SubtreeInfo leaf = childInfo(p, makeLeafRef(s));
    RootInfo r;
    r.box = leaf.box;
    r.ref = leaf.ref;
    r.count = 1;
    r.interiorCount = 0;
    r.depth = 0;
    *p.root = r;
    return;
  }
  for (;;) {
    const uint32_t node = slot >> 1;
    ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> arrivals(p.counters[node]);
    if (arrivals.fetch_add(1, ::cuda::memory_order_acq_rel) == 0) return;  // the sibling's thread goes on
    const int2 ch = p.children[node];
    const SubtreeInfo a = childInfo(p, ch.x), b = childInfo(p, ch.y);
    SubtreeInfo self;
    self.box = merge(a.box, b.box);
    self.count = a.count + b.count;
    self.first = min(a.first, b.first);
    const float area = self.box.area();
    const float keep = p.ct * area + a.cost + b.cost;
    const float asLeaf = p.ci * float(self.count) * area;
    const bool collapse = Collapse && self.count <= p.maxLeafSize && asLeaf <= keep;
    self.cost = collapse ? asLeaf : keep;
    self.ref = collapse ? makeLeafRef(self.first) : int32_t(node);
    self.interior = collapse ? 0u : 1u + a.interior + b.interior;
    self.height = collapse ? 0u : 1u + max(a.height, b.height);

    // The node as the traversal reads it (unreferenced when an ancestor collapses).
    float4* out = reinterpret_cast<float4*>(p.nodes + node);
    out[0] = make_float4(a.box.lo.x, a.box.hi.x, a.box.lo.y, a.box.hi.y);
    out[1] = make_float4(b.box.lo.x, b.box.hi.x, b.box.lo.y, b.box.hi.y);
    out[2] = make_float4(a.box.lo.z, a.box.hi.z, b.box.lo.z, b.box.hi.z);
    out[3] = make_float4(__int_as_float(a.ref), __int_as_float(b.ref),
                         __uint_as_float(isLeafRef(a.ref) ? a.count : 0u),
                         __uint_as_float(isLeafRef(b.ref) ? b.count : 0u));
    storeInfo(p.info, node, self);

    slot = p.nodeParent[node];
    if (slot == kNoParent) {
      RootInfo r;
      r.box = self.box;
      r.ref = self.ref;
      r.count = isLeafRef(self.ref) ? self.count : 0u;
      r.interiorCount = self.interior;
      r.depth = self.height;
      *p.root = r;
      return;
    }
  }
}

}  // namespace

GpuRebuilder::GpuRebuilder(uint32_t triangles, TreeLayout layout) : n_(triangles), events_(8) {  // see collect
  if (n_ == 0) throw tsah::DataError("GPU rebuild: no triangles");
  if (n_ > kMaxGpuTriangles) throw tsah::DataError("GPU rebuild: too many triangles");
  const std::size_t n = n_;
  const std::size_t clusterCap = std::min<std::size_t>(n, kMaxClusters);
  const std::size_t nodeCap = std::max<std::size_t>(1, (n - 1) + (clusterCap - 1));
  triBox_.resize(n);
  mortonIn_.resize(n);
  mortonOut_.resize(n);
  idsIn_.resize(n);
  sortedIds_.resize(n);
  slotTri_.resize(n);
  leafParent_.resize(n);
  centroidBounds_.resize(6);
  children_.resize(nodeCap);
  nodeParent_.resize(nodeCap);
  counters_.resize(nodeCap);
  nodeInfo_.resize(3 * nodeCap);
  nodes_.resize(nodeCap);
  root_.resize(1);
  // HLBVH-SAH.
  headFlags_.resize(n);
  clusterOf_.resize(n);
  leafParentRadix_.resize(n);
  slotMap_.resize(n);
  nodeRange_.resize(std::max<std::size_t>(1, n - 1));
  for (auto* b : {&clusterBegin_, &clusterEnd_, &clusterCell_, &clusterParent_, &orderA_, &orderB_, &finalOrder_,
                  &newBegin_, &taskReady_})
    b->resize(clusterCap);
  clusterRoot_.resize(clusterCap);
  clusterBox_.resize(clusterCap);
  tasks_.resize(clusterCap);
  queueWords_.resize(kQueueWords);

  std::size_t sortBytes = 0, scanBytes = 0;
  CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, sortBytes, mortonIn_.data(), mortonOut_.data(), idsIn_.data(),
                                             sortedIds_.data(), int64_t(n), 0, kMortonBits));
  CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, scanBytes, headFlags_.data(), clusterOf_.data(), int64_t(n)));
  cubTemp_.resize(std::max<std::size_t>({sortBytes, scanBytes, 1}));
  // More than a few blocks per multiprocessor would only add blocks spinning on the queue.
  topBlocks_ = residentBlocks(clusterTreeKernel, kTopBlock, 4);
  int device = 0, sms = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  boxBlocks_ = 8 * sms;
  if (layout == TreeLayout::Cwbvh) wide_ = std::make_unique<GpuCwbvhConverter>(n_);
}

GpuRebuilder::~GpuRebuilder() = default;

void GpuRebuilder::enqueue(const uint32_t* indices, const float* positions, const RebuildOptions& options,
                           WoopTriangle* woop, cudaStream_t stream) {
  if (options.maxLeafSize == 0) throw tsah::ConfigError("GPU rebuild: maxLeafSize must be at least 1");
  const bool wide = wide_ != nullptr;
  if (wide && options.collapse && options.maxLeafSize > kCwbvhMaxLeafTriangles)
    throw tsah::ConfigError("GPU rebuild: the cwbvh layout takes leaves of at most " +
                            std::to_string(kCwbvhMaxLeafTriangles) + " triangles (maxLeafSize is " +
                            std::to_string(options.maxLeafSize) + ")");
  const bool hlbvh = options.method == RebuildMethod::HlbvhSah;
  const uint32_t n = n_;
  const unsigned block = 256;
  built_ = false;

  events_.record(0, stream);
  // Morton codes over the centroid bounds.
  centroidBounds_.fillBytes(0x7f, stream);
  triangleBoxesKernel<<<std::min<unsigned>(gridFor(n, kBoxBlock), unsigned(boxBlocks_)), kBoxBlock, 0, stream>>>(
      indices, positions, n, triBox_.data(), centroidBounds_.data());
  CUDA_CHECK_LAUNCH("triangleBoxesKernel");
  mortonKernel<<<gridFor(n, block), block, 0, stream>>>(triBox_.data(), n, centroidBounds_.data(), mortonIn_.data(),
                                                        idsIn_.data());
  CUDA_CHECK_LAUNCH("mortonKernel");
  events_.record(1, stream);

  std::size_t tempBytes = cubTemp_.size();
  CUDA_CHECK(cub::DeviceRadixSort::SortPairs(cubTemp_.data(), tempBytes, mortonIn_.data(), mortonOut_.data(),
                                             idsIn_.data(), sortedIds_.data(), int64_t(n), 0, kMortonBits, stream));
  events_.record(2, stream);

  const uint32_t* keys = mortonOut_.data();
  if (hlbvh) {
    clusterHeadsKernel<<<gridFor(n, block), block, 0, stream>>>(keys, n, headFlags_.data());
    CUDA_CHECK_LAUNCH("clusterHeadsKernel");
    tempBytes = cubTemp_.size();
    CUDA_CHECK(cub::DeviceScan::InclusiveSum(cubTemp_.data(), tempBytes, headFlags_.data(), clusterOf_.data(),
                                             int64_t(n), stream));
    taskReady_.fillBytes(0, stream);
    ClusterSetup setup{clusterBegin_.data(), clusterEnd_.data(), clusterCell_.data(), clusterRoot_.data(),
                       clusterParent_.data(), orderA_.data(), finalOrder_.data(), tasks_.data(),
                       taskReady_.data(), queueWords_.data()};
    clusterSetupKernel<<<gridFor(n, block), block, 0, stream>>>(keys, n, clusterOf_.data(), setup);
    CUDA_CHECK_LAUNCH("clusterSetupKernel");
  }
  if (n >= 2) {
    KarrasOutput out{children_.data(), nodeParent_.data(), hlbvh ? leafParentRadix_.data() : leafParent_.data(),
                     hlbvh ? nodeRange_.data() : nullptr, clusterOf_.data(), clusterRoot_.data()};
    karrasKernel<<<gridFor(n - 1, block), block, 0, stream>>>(keys, n, out);
    CUDA_CHECK_LAUNCH("karrasKernel");
  } else {  // one triangle: no interior node; 0xff bytes are kNoParent
    CUDA_CHECK(cudaMemsetAsync(hlbvh ? leafParentRadix_.data() : leafParent_.data(), 0xff, sizeof(uint32_t), stream));
  }
  events_.record(3, stream);

  if (hlbvh) {
    clusterBoxKernel<<<gridFor(std::min<std::size_t>(n, kMaxClusters) * 32, block), block, 0, stream>>>(
        sortedIds_.data(), triBox_.data(), clusterBegin_.data(), clusterEnd_.data(), queueWords_.data(),
        clusterBox_.data());
    CUDA_CHECK_LAUNCH("clusterBoxKernel");
    TopParams top{clusterBegin_.data(), clusterEnd_.data(), clusterCell_.data(), clusterBox_.data(),
                  clusterRoot_.data(), orderA_.data(), orderB_.data(), finalOrder_.data(), clusterParent_.data(),
                  children_.data(), nodeParent_.data(), n - 1, tasks_.data(), taskReady_.data(),
                  queueWords_.data()};
    clusterTreeKernel<<<unsigned(topBlocks_), kTopBlock, 0, stream>>>(top);
    CUDA_CHECK_LAUNCH("clusterTreeKernel");
    clusterSlotsKernel<<<1, kOrderBlock, 0, stream>>>(finalOrder_.data(), clusterBegin_.data(), clusterEnd_.data(),
                                                      queueWords_.data(), newBegin_.data());
    CUDA_CHECK_LAUNCH("clusterSlotsKernel");
    permuteKernel<<<gridFor(n, block), block, 0, stream>>>(n, clusterOf_.data(), clusterBegin_.data(),
                                                           clusterEnd_.data(), newBegin_.data(), clusterParent_.data(),
                                                           sortedIds_.data(), leafParentRadix_.data(), slotTri_.data(),
                                                           slotMap_.data(), leafParent_.data());
    CUDA_CHECK_LAUNCH("permuteKernel");
    if (n >= 2) {
      const std::size_t nodesUpperBound = (n - 1) + std::min<std::size_t>(n, kMaxClusters) - 1;
      remapKernel<<<gridFor(nodesUpperBound, block), block, 0, stream>>>(
          n, keys, nodeRange_.data(), clusterOf_.data(), clusterRoot_.data(), clusterParent_.data(),
          queueWords_.data(), slotMap_.data(), children_.data(), nodeParent_.data());
      CUDA_CHECK_LAUNCH("remapKernel");
    }
  } else {
    CUDA_CHECK(cudaMemcpyAsync(slotTri_.data(), sortedIds_.data(), std::size_t(n) * sizeof(uint32_t),
                               cudaMemcpyDeviceToDevice, stream));
  }
  events_.record(4, stream);

  counters_.fillBytes(0, stream);
  BottomUpParams bu{n,
                    slotTri_.data(),
                    leafParent_.data(),
                    triBox_.data(),
                    children_.data(),
                    nodeParent_.data(),
                    counters_.data(),
                    nodeInfo_.data(),
                    nodes_.data(),
                    root_.data(),
                    options.cost.ct,
                    options.cost.ci,
                    options.maxLeafSize};
  if (options.collapse)
    bottomUpKernel<true><<<gridFor(n, block), block, 0, stream>>>(bu);
  else
    bottomUpKernel<false><<<gridFor(n, block), block, 0, stream>>>(bu);
  CUDA_CHECK_LAUNCH("bottomUpKernel");
  events_.record(5, stream);

  // The wide layout: the binary nodes' array (unreferenced nodes are never read), then the Woop
  // triangles of the wide layout's slots.
  if (wide)
    wide_->enqueue(nodes_.data(), uint32_t(nodes_.size()), slotTri_.data(), root_.data(), options.wideMergeTriangles,
                   stream);
  events_.record(6, stream);
  if (options.woop) launchWoop(wide ? wide_->triIndex() : slotTri_.data(), n, indices, positions, woop, stream);
  events_.record(7, stream);
}

RebuildTimings GpuRebuilder::collect(const RebuildOptions& options) {
  const bool hlbvh = options.method == RebuildMethod::HlbvhSah;
  RebuildTimings timings;
  events_.wait(7);

  timings.mortonMs = events_.ms(0, 1);
  timings.sortMs = events_.ms(1, 2);
  timings.hierarchyMs = events_.ms(2, 3);
  timings.topMs = events_.ms(3, 4);
  timings.bottomUpMs = events_.ms(4, 5);
  timings.wideMs = wide_ ? events_.ms(5, 6) : 0.0;  // without a conversion, two events back to back
  timings.woopMs = events_.ms(6, 7);
  RootInfo root;
  CUDA_CHECK(cudaMemcpy(&root, root_.data(), sizeof root, cudaMemcpyDeviceToHost));
  timings.interiorNodes = root.interiorCount;
  timings.leaves = root.interiorCount + 1;
  timings.depth = root.depth;
  if (hlbvh) {
    uint32_t clusters = 0;
    CUDA_CHECK(cudaMemcpy(&clusters, queueWords_.data() + kClusterCount, sizeof clusters, cudaMemcpyDeviceToHost));
    timings.clusters = clusters;
  }
  if (root.depth > kTraversalStackSize)
    throw tsah::Failure("GPU rebuild: the tree is " + std::to_string(root.depth) +
                        " levels deep, more than the traversal stack of " + std::to_string(kTraversalStackSize));
  // The wide tree is no deeper than the binary one (every wide child starts below its parent's
  // binary node), so the check above bounds the wide traversal's stack too.
  if (wide_) {
    timings.wideNodes = wide_->collect(nullptr);
    timings.wideLevels = wide_->levels();
  }
  built_ = true;
  return timings;
}

RebuildTimings GpuRebuilder::build(const uint32_t* indices, const float* positions, const RebuildOptions& options,
                                   WoopTriangle* woop, cudaStream_t stream) {
  enqueue(indices, positions, options, woop, stream);
  return collect(options);
}

FlatBvh GpuRebuilder::downloadArrays(cudaStream_t stream) const {
  if (!built_) throw tsah::ConfigError("GPU rebuild: no tree has been built");
  const RootInfo root = root_.download(stream)[0];
  FlatBvh raw;
  raw.nodes = nodes_.download(stream);
  raw.interiorCount = uint32_t(raw.nodes.size());
  raw.leafCount = root.interiorCount + 1;
  raw.depth = root.depth;
  raw.rootRef = root.ref;
  raw.rootCount = root.count;
  raw.rootBoxes = {root.box};
  raw.triIndex = slotTri_.download(stream);
  return raw;
}

Bvh GpuRebuilder::download(cudaStream_t stream) const {
  if (!built_) throw tsah::ConfigError("GPU rebuild: no tree has been built");
  const std::vector<GpuBvhNode> nodes = nodes_.download(stream);
  const std::vector<RootInfo> root = root_.download(stream);
  Bvh bvh;
  bvh.frameCount = 1;
  bvh.primIds = slotTri_.download(stream);
  bvh.root = 0;
  auto addNode = [&](uint32_t parent, const Aabb& box) {
    bvh.nodes.emplace_back().parent = parent;
    bvh.boxes.push_back(box);
    return uint32_t(bvh.nodes.size() - 1);
  };
  const uint32_t rootIndex = addNode(kInvalidIndex, root[0].box);
  // (device reference, leaf count, Bvh index) of nodes still to expand.
  struct Item {
    int32_t ref;
    uint32_t count, index;
  };
  std::vector<Item> stack{{root[0].ref, root[0].count, rootIndex}};
  const std::size_t limit = nodes.size() + 1;
  std::size_t interiorSeen = 0;
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    if (isLeafRef(item.ref)) {
      const uint32_t first = leafFirstSlot(item.ref);
      if (item.count == 0 || std::size_t(first) + item.count > n_)
        throw tsah::Failure("GPU rebuild: a leaf's slot range is out of bounds");
      bvh.nodes[item.index].primBegin = first;
      bvh.nodes[item.index].primCount = item.count;
      continue;
    }
    if (uint32_t(item.ref) >= nodes.size() || ++interiorSeen > limit)
      throw tsah::Failure("GPU rebuild: a node reference is out of range or the nodes form a cycle");
    const GpuBvhNode& node = nodes[uint32_t(item.ref)];
    const uint32_t left = addNode(item.index, node.childBox(0));
    const uint32_t right = addNode(item.index, node.childBox(1));
    bvh.nodes[item.index].left = left;
    bvh.nodes[item.index].right = right;
    stack.push_back({node.ref1, node.count1, right});
    stack.push_back({node.ref0, node.count0, left});
  }
  return bvh;
}

}  // namespace tsah::cuda::detail
