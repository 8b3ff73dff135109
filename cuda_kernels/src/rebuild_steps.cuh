#pragma once
// The steps of the per-frame GPU rebuilds (rebuild.hpp) shared by their files: constants, the
// device helpers of more than one step, the steps' parameters and their launchers (rebuild_*.cu).
// CUDA sources only. Every launcher checks its launch and throws CudaError; none synchronizes.
#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>

#include "device_types.hpp"

namespace tsah::cuda::detail {

inline constexpr int kMortonBits = 30;    // 10 per axis
inline constexpr int kClusterShift = 15;  // HLBVH-SAH clusters: the top 15 of the 30 bits (5 per axis)
inline constexpr uint32_t kMaxClusters = 1u << 15;
inline constexpr unsigned kRebuildBlock = 256;  // threads per block of the kernels with a thread per item

// Cluster words: clusterCount, queue head, queue tail.
enum QueueWord { kClusterCount = 0, kQueueHead = 1, kQueueTail = 2, kTasksDone = 3, kQueueWords = 4 };

// --- Device helpers ------------------------------------------------------------------------------

// Floats as ints whose signed order is the float order, so atomicMin works on floats.
__device__ __forceinline__ int orderedInt(float f) {
  const int i = __float_as_int(f);
  return i >= 0 ? i : i ^ 0x7fffffff;
}
__device__ __forceinline__ float orderedFloat(int i) { return __int_as_float(i >= 0 ? i : i ^ 0x7fffffff); }

// 0x7f7f7f7f (what cudaMemset(0x7f) writes) as an ordered int is a huge positive float: the
// starting value of a minimum.
inline constexpr int kOrderedHuge = 0x7f7f7f7f;

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

// 10 bits spread to every third bit (Morton codes), and back (a cluster's grid cell).
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

__device__ __forceinline__ uint32_t clusterKey(uint32_t code) { return code >> kClusterShift; }

// --- Morton codes and sort (rebuild_morton.cu) ----------------------------------------------------

// Triangle boxes (triBox, by triangle id) and the bounds of their centroids (centroidBounds: six
// ordered ints, min xyz and min -xyz, holding kOrderedHuge on entry) in at most maxBoxBlocks
// blocks, then every triangle's 30-bit Morton code over those bounds (codes) and its id (ids).
void launchMortonCodes(const uint32_t* indices, const float* positions, uint32_t n, unsigned maxBoxBlocks,
                       Aabb* triBox, int32_t* centroidBounds, uint32_t* codes, uint32_t* ids, cudaStream_t stream);
// The same over given boxes (n, by primitive id): the same kernels, the boxes read instead of computed.
void launchMortonCodes(const Aabb* boxes, uint32_t n, unsigned maxBoxBlocks, int32_t* centroidBounds, uint32_t* codes,
                       uint32_t* ids, cudaStream_t stream);

// CUB's radix sort of n codes (their low kMortonBits bits) with their ids. temp == nullptr: only
// sets tempBytes to the scratch the sort needs.
void sortMortonCodes(void* temp, std::size_t& tempBytes, const uint32_t* codesIn, uint32_t* codesOut,
                     const uint32_t* idsIn, uint32_t* idsOut, uint32_t n, cudaStream_t stream);

// --- Karras radix tree (rebuild_radix_tree.cu) ----------------------------------------------------

struct KarrasOutput {
  int2* children;
  uint32_t* nodeParent;
  uint32_t* leafParent;
  // HLBVH-SAH only (null for LBVH):
  uint2* nodeRange;
  const uint32_t* clusterOf;
  int32_t* clusterRoot;
};

// The radix tree over n >= 2 sorted keys: node i's children and every node's and leaf's parent
// slot (node * 2 + side); with out.nodeRange, each node's key range and each cluster's root.
void launchRadixTree(const uint32_t* keys, uint32_t n, const KarrasOutput& out, cudaStream_t stream);

// --- HLBVH-SAH clusters and cluster tree (rebuild_hlbvh_sah.cu) -----------------------------------

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

// heads: 1 where a cluster starts after slot 0 (the runs of equal clusterKey among n sorted keys).
void launchClusterHeads(const uint32_t* keys, uint32_t n, uint32_t* heads, cudaStream_t stream);
// CUB's inclusive sum of the n heads: the cluster of every slot. temp == nullptr: only sets
// tempBytes to the scratch the sum needs.
void scanClusterHeads(void* temp, std::size_t& tempBytes, const uint32_t* heads, uint32_t* clusterOf, uint32_t n,
                      cudaStream_t stream);
// Every cluster's slot range, grid cell and initial order, and the cluster tree's root task
// (out.taskReady zero on entry).
void launchClusterSetup(const uint32_t* keys, uint32_t n, const uint32_t* clusterOf, const ClusterSetup& out,
                        cudaStream_t stream);
// The union of every cluster's primitive boxes (n primitives; primBox by primitive id).
void launchClusterBoxes(const uint32_t* sortedIds, const Aabb* primBox, const uint32_t* clusterBegin,
                        const uint32_t* clusterEnd, const uint32_t* words, Aabb* clusterBox, uint32_t n,
                        cudaStream_t stream);
// The blocks of the cluster-tree builder on the current device (resident together).
int clusterTreeBlocks();
// The binned SAH tree over the clusters, by `blocks` persistent blocks (clusterTreeBlocks()).
void launchClusterTree(const TopParams& p, int blocks, cudaStream_t stream);
// New first slot of every cluster (newBegin) in the cluster tree's leaf order.
void launchClusterSlots(const uint32_t* finalOrder, const uint32_t* clusterBegin, const uint32_t* clusterEnd,
                        const uint32_t* words, uint32_t* newBegin, cudaStream_t stream);
// The triangles to their final slots (slotTri, slotMap: radix slot -> final slot, leafParent).
void launchPermute(uint32_t n, const uint32_t* clusterOf, const uint32_t* clusterBegin, const uint32_t* clusterEnd,
                   const uint32_t* newBegin, const uint32_t* clusterParent, const uint32_t* sortedIds,
                   const uint32_t* leafParentRadix, uint32_t* slotTri, uint32_t* slotMap, uint32_t* leafParent,
                   cudaStream_t stream);
// The radix tree's leaf references to the final slots, the cluster roots' parents in the cluster
// tree (n >= 2).
void launchRemap(uint32_t n, const uint32_t* keys, const uint2* nodeRange, const uint32_t* clusterOf,
                 const int32_t* clusterRoot, const uint32_t* clusterParent, const uint32_t* words,
                 const uint32_t* slotMap, int2* children, uint32_t* nodeParent, cudaStream_t stream);

// --- Bottom-up boxes, leaf collapse, node output (rebuild_bottom_up.cu) ---------------------------

struct BottomUpParams {
  uint32_t n;
  const uint32_t* slotTri;
  const uint32_t* leafParent;
  const Aabb* primBox;  // by primitive id: the triangles' boxes, or the given boxes
  const int2* children;
  const uint32_t* nodeParent;
  uint32_t* counters;
  uint4* info;
  GpuBvhNode* nodes;
  RootInfo* root;
  float ct, ci;
  uint32_t maxLeafSize;
};

// One thread per slot climbs to the root (p.counters zero on entry): every interior node's child
// boxes and GpuBvhNode, the SAH leaf collapse when `collapse` (leaves of at most p.maxLeafSize
// triangles), and the root.
void launchBottomUp(const BottomUpParams& p, bool collapse, cudaStream_t stream);

}  // namespace tsah::cuda::detail
