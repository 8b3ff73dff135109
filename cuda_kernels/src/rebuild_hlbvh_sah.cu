// HLBVH-SAH above the radix tree: the clusters (runs of equal top-15-bit Morton prefixes), the
// binned SAH tree over them by persistent blocks, and the triangles reordered into its leaf order.
#include <cub/block/block_scan.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda/atomic>

#include <algorithm>

#include "launch.hpp"
#include "rebuild_steps.cuh"

namespace tsah::cuda::detail {

namespace {

constexpr int kTopBlock = 128;          // threads of a block of the cluster-tree builder
constexpr int kTopBins = 32;            // grid cells per axis at the cluster level (5 bits)

__global__ void clusterHeadsKernel(const uint32_t* __restrict__ keys, uint32_t n, uint32_t* __restrict__ heads) {
  const uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  // 1 where a new cluster starts (never at 0), so the inclusive sum is the cluster index.
  heads[s] = s > 0 && clusterKey(__ldg(keys + s)) != clusterKey(__ldg(keys + s - 1)) ? 1u : 0u;
}

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

// One warp per cluster: the union of its primitives' boxes.
__global__ void clusterBoxKernel(const uint32_t* __restrict__ sortedIds, const Aabb* __restrict__ primBox,
                                 const uint32_t* __restrict__ clusterBegin, const uint32_t* __restrict__ clusterEnd,
                                 const uint32_t* __restrict__ words, Aabb* __restrict__ clusterBox) {
  const uint32_t clusters = words[kClusterCount];
  const uint32_t lane = threadIdx.x & 31u;
  const uint32_t warps = (gridDim.x * blockDim.x) >> 5;
  for (uint32_t c = (blockIdx.x * blockDim.x + threadIdx.x) >> 5; c < clusters; c += warps) {
    const uint32_t end = clusterEnd[c];
    float m[6] = {3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f, 3.0e38f};
    for (uint32_t s = clusterBegin[c] + lane; s < end; s += 32) {
      const Aabb b = loadBox(primBox, __ldg(sortedIds + s));
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

}  // namespace

void launchClusterHeads(const uint32_t* keys, uint32_t n, uint32_t* heads, cudaStream_t stream) {
  clusterHeadsKernel<<<gridFor(n, kRebuildBlock), kRebuildBlock, 0, stream>>>(keys, n, heads);
  CUDA_CHECK_LAUNCH("clusterHeadsKernel");
}

void scanClusterHeads(void* temp, std::size_t& tempBytes, const uint32_t* heads, uint32_t* clusterOf, uint32_t n,
                      cudaStream_t stream) {
  CUDA_CHECK(cub::DeviceScan::InclusiveSum(temp, tempBytes, heads, clusterOf, int64_t(n), stream));
}

void launchClusterSetup(const uint32_t* keys, uint32_t n, const uint32_t* clusterOf, const ClusterSetup& out,
                        cudaStream_t stream) {
  clusterSetupKernel<<<gridFor(n, kRebuildBlock), kRebuildBlock, 0, stream>>>(keys, n, clusterOf, out);
  CUDA_CHECK_LAUNCH("clusterSetupKernel");
}

void launchClusterBoxes(const uint32_t* sortedIds, const Aabb* primBox, const uint32_t* clusterBegin,
                        const uint32_t* clusterEnd, const uint32_t* words, Aabb* clusterBox, uint32_t n,
                        cudaStream_t stream) {
  clusterBoxKernel<<<gridFor(std::min<std::size_t>(n, kMaxClusters) * 32, kRebuildBlock), kRebuildBlock, 0, stream>>>(
      sortedIds, primBox, clusterBegin, clusterEnd, words, clusterBox);
  CUDA_CHECK_LAUNCH("clusterBoxKernel");
}

// More than a few blocks per multiprocessor would only add blocks spinning on the queue.
int clusterTreeBlocks() { return residentBlocks(clusterTreeKernel, kTopBlock, 4); }

void launchClusterTree(const TopParams& p, int blocks, cudaStream_t stream) {
  clusterTreeKernel<<<unsigned(blocks), kTopBlock, 0, stream>>>(p);
  CUDA_CHECK_LAUNCH("clusterTreeKernel");
}

void launchClusterSlots(const uint32_t* finalOrder, const uint32_t* clusterBegin, const uint32_t* clusterEnd,
                        const uint32_t* words, uint32_t* newBegin, cudaStream_t stream) {
  clusterSlotsKernel<<<1, kOrderBlock, 0, stream>>>(finalOrder, clusterBegin, clusterEnd, words, newBegin);
  CUDA_CHECK_LAUNCH("clusterSlotsKernel");
}

void launchPermute(uint32_t n, const uint32_t* clusterOf, const uint32_t* clusterBegin, const uint32_t* clusterEnd,
                   const uint32_t* newBegin, const uint32_t* clusterParent, const uint32_t* sortedIds,
                   const uint32_t* leafParentRadix, uint32_t* slotTri, uint32_t* slotMap, uint32_t* leafParent,
                   cudaStream_t stream) {
  permuteKernel<<<gridFor(n, kRebuildBlock), kRebuildBlock, 0, stream>>>(
      n, clusterOf, clusterBegin, clusterEnd, newBegin, clusterParent, sortedIds, leafParentRadix, slotTri, slotMap,
      leafParent);
  CUDA_CHECK_LAUNCH("permuteKernel");
}

void launchRemap(uint32_t n, const uint32_t* keys, const uint2* nodeRange, const uint32_t* clusterOf,
                 const int32_t* clusterRoot, const uint32_t* clusterParent, const uint32_t* words,
                 const uint32_t* slotMap, int2* children, uint32_t* nodeParent, cudaStream_t stream) {
  const std::size_t nodesUpperBound = (n - 1) + std::min<std::size_t>(n, kMaxClusters) - 1;
  remapKernel<<<gridFor(nodesUpperBound, kRebuildBlock), kRebuildBlock, 0, stream>>>(
      n, keys, nodeRange, clusterOf, clusterRoot, clusterParent, words, slotMap, children, nodeParent);
  CUDA_CHECK_LAUNCH("remapKernel");
}

}  // namespace tsah::cuda::detail
