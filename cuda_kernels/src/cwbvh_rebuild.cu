// The conversion of a rebuilt binary tree into the compressed 8-wide layout (see
// cwbvh_rebuild.hpp). One persistent kernel: all its blocks are resident at once (occupancy
// calculator, as the HLBVH-SAH cluster builder), so a software grid barrier separates the steps
// of a level; the number of levels is never known on the host, which keeps the work capturable.
#include <cub/block/block_scan.cuh>
#include <cuda/atomic>

#include <algorithm>
#include <string>

#include "tsah/base/error.hpp"
#include "cwbvh_lanes.cuh"
#include "cwbvh_rebuild.hpp"
#include "launch.hpp"

namespace tsah::cuda::detail {

namespace {

constexpr int kConvertBlock = 128;
// Resident blocks per multiprocessor (all blocks must be resident: the grid barrier). A round
// opens 16 nodes per block, so the widest levels of large trees want several blocks per SM; more
// blocks make each barrier dearer. Measured on an H200 (LBVH rebuilds, conversion ms; 2 / 4 / 8
// per SM): Kitchen 0.170 / 0.167 / 0.195, Robots 0.194 / 0.208 / 0.214, 1M triangles 0.500 /
// 0.359 / 0.333; one block with its own barrier only (16 nodes per round): faerie 0.065 against
// 0.057, Kitchen 6.6 ms.
constexpr int kConvertBlocksPerSm = 4;
enum ConvertWord : uint32_t {
  kArrivals = 0,
  kGeneration = 1,
  kNodeCountWord = 2,
  kErrorWord = 3,
  kLevelsWord = 4,
  kConvertWords = 5
};

// Every block waits until all blocks have arrived; writes before it are visible after it (read
// them through L2 with __ldcg: another block's writes never sit in this SM's L1).
__device__ void gridBarrier(uint32_t* words) {
  __syncthreads();
  if (gridDim.x == 1) return;  // one block: its barrier is enough
  if (threadIdx.x == 0) {
    ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> arrivals(words[kArrivals]);
    ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device> generation(words[kGeneration]);
    __threadfence();
    const uint32_t g = generation.load(::cuda::memory_order_acquire);
    if (arrivals.fetch_add(1u, ::cuda::memory_order_acq_rel) == gridDim.x - 1) {
      arrivals.store(0u, ::cuda::memory_order_relaxed);
      generation.store(g + 1u, ::cuda::memory_order_release);
    } else {
      uint32_t spins = 0;
      while (generation.load(::cuda::memory_order_acquire) == g) {
        if (++spins == (1u << 30)) __trap();  // a bug, not a wait: fail the launch instead of hanging
        __nanosleep(32);
      }
    }
    __threadfence();
  }
  __syncthreads();
}

__device__ __forceinline__ uint32_t warpSum(uint32_t v) {
  for (int o = 16; o > 0; o >>= 1) v += __shfl_xor_sync(0xffffffffu, v, o);
  return v;
}

struct ConvertParams {
  BinaryTreeView tree;
  const RootInfo* root;
  CwbvhConvertOutput out;  // nodes, starts, triIndex
  uint2* blockSums;        // 2 * gridDim.x
  uint32_t* words;
  uint32_t mergeLimit;
  uint32_t maxNodes;       // capacity of out.nodes and out.starts
};

// One wide node, opened by the 8 lanes of a group: the steps of cwbvhOpen and cwbvhWriteNode
// (tsah/cwbvh_convert.hpp) with a lane per child, so a level waits for a few dependent loads and a
// few hundred instructions per lane instead of one thread's ~10k. The bits are the serial code's
// (the GPU tests compare the nodes with tsah::convertToCwbvh byte for byte).
constexpr uint32_t kGroupLanes = kCwbvhWidth;
constexpr uint32_t kGroupsPerBlock = kConvertBlock / kGroupLanes;

// Lane c's value of the group (c: 0-7, a constant when unrolled).
template <class T>
__device__ __forceinline__ T fromLane(uint32_t groupMask, T v, uint32_t c) {
  return __shfl_sync(groupMask, v, int(c), int(kGroupLanes));
}

__device__ __forceinline__ uint64_t maxOverGroup(uint32_t groupMask, uint64_t v) {
#pragma unroll
  for (uint32_t w = kGroupLanes / 2; w >= 1; w /= 2) {
    const uint64_t other = __shfl_xor_sync(groupMask, v, int(w), int(kGroupLanes));
    v = other > v ? other : v;
  }
  return v;
}

__device__ __forceinline__ uint32_t sumOverGroup(uint32_t groupMask, uint32_t v) {
#pragma unroll
  for (uint32_t w = kGroupLanes / 2; w >= 1; w /= 2) v += __shfl_xor_sync(groupMask, v, int(w), int(kGroupLanes));
  return v;
}

// In the functions below, `member` is the calling lane's index in its group of 8 (0-7).

// The children of the wide node starting at `start` (cwbvhOpen's opening): member c gets child c
// in opening order (`mine`), every member the count n. The widest interior child (the first of the
// largest area, as the serial fold over c = 0..n-1 picks it) is opened until there are 8.
// Returns false, in every lane of the group, for an invalid reference.
__device__ bool openLanes(const BinaryTreeView& t, int32_t start, uint32_t count, const Aabb& box, uint32_t mergeLimit,
                          uint32_t member, uint32_t groupMask, CwbvhOpenChild& mine, uint32_t& n) {
  mine = {0, 0, Aabb{}};
  if (isLeafRef(start)) {  // a tree that is one leaf
    if (member == 0) mine = {start, count, box};
    n = 1;
    return true;
  }
  if (uint32_t(start) >= t.nodeCount) return false;
  float area = 0.0f;
  const GpuBvhNode root = tsah::detail::cwbvhLoadBinaryNode(t.nodes, uint32_t(start));
  if (member < 2) {
    mine = tsah::detail::cwbvhBinaryChild(t, root, int(member), mergeLimit);
    area = mine.box.area();
  }
  n = 2;
  while (n < kCwbvhWidth) {
    const int candidate = member < n && !isLeafRef(mine.ref) ? 1 : 0;
    int widest = -1;
    float widestArea = 0.0f;
#pragma unroll
    for (uint32_t c = 0; c < kGroupLanes; ++c) {
      const int isCandidate = fromLane(groupMask, candidate, c);
      const float a = fromLane(groupMask, area, c);
      if (isCandidate && (widest < 0 || a > widestArea)) {
        widest = int(c);
        widestArea = a;
      }
    }
    if (widest < 0) break;
    const int32_t widestRef = __shfl_sync(groupMask, mine.ref, widest, int(kGroupLanes));
    if (uint32_t(widestRef) >= t.nodeCount) return false;
    const GpuBvhNode node = tsah::detail::cwbvhLoadBinaryNode(t.nodes, uint32_t(widestRef));
    if (member == uint32_t(widest) || member == n) {
      mine = tsah::detail::cwbvhBinaryChild(t, node, member == n ? 1 : 0, mergeLimit);
      area = mine.box.area();
    }
    ++n;
  }
  return true;
}

// cwbvhAssignSlots with a member per child (row): each round every member offers the best key of
// its row among the free slots and the group takes the largest (max is associative: the serial tree
// of maxima picks the same pair). Returns this member's child's slot.
__device__ uint32_t assignSlotLanes(const Vec3& offset, uint32_t n, uint32_t member, uint32_t groupMask) {
  uint32_t score[kCwbvhWidth];
#pragma unroll
  for (uint32_t s = 0; s < kCwbvhWidth; ++s) score[s] = cwbvhSlotScore(offset, s);
  uint32_t usedSlots = 0, assigned = 0, mySlot = 0;
  for (uint32_t round = 0; round < n; ++round) {
    const bool freeRow = member < n && !((assigned >> member) & 1u);
    uint64_t rowBest = 0;
#pragma unroll
    for (uint32_t s = 0; s < kCwbvhWidth; ++s)
      if (freeRow && !((usedSlots >> s) & 1u)) rowBest = cwbvhMax64(rowBest, cwbvhSlotKey(score[s], member, s));
    const uint32_t pair = cwbvhKeyPair(maxOverGroup(groupMask, rowBest));
    if (member == pair >> 3) mySlot = pair & 7u;
    assigned |= 1u << (pair >> 3);
    usedSlots |= 1u << (pair & 7u);
  }
  return mySlot;
}

// A wide node's children by slot, in the members of its group (member s: slot s).
struct SlotChild {
  CwbvhOpenChild child{0, 0u, Aabb{}};
  bool occupied = false;
};

// Opens the node and puts its children into their slots (cwbvhOpen). interior / triangles: the
// node's interior children and leaf triangles. Returns false (every lane) when the tree is invalid.
__device__ bool openNodeLanes(const BinaryTreeView& t, int32_t start, uint32_t count, const Aabb& box,
                              uint32_t mergeLimit, uint32_t member, uint32_t groupMask, SlotChild& out,
                              uint32_t& interior, uint32_t& triangles) {
  CwbvhOpenChild mine;
  uint32_t n = 0;
  if (!openLanes(t, start, count, box, mergeLimit, member, groupMask, mine, n)) return false;
  const bool has = member < n, isInterior = has && !isLeafRef(mine.ref);
  const bool valid = !has || (isInterior ? uint32_t(mine.ref) < t.nodeCount
                                         : tsah::detail::cwbvhLeafInRange(t, mine.ref, mine.count));
  interior = uint32_t(__popc(__ballot_sync(groupMask, isInterior)));
  triangles = sumOverGroup(groupMask, has && !isInterior ? mine.count : 0u);
  if (__ballot_sync(groupMask, !valid) != 0 || triangles > kCwbvhMaxNodeTriangles) return false;
  // cwbvhAddCentreOffsets: this child's offset from the centre of the children's union (min and
  // max in any order give the same union; a zero's sign cannot change a slot key).
  Aabb all = has ? mine.box : Aabb{};
#pragma unroll
  for (uint32_t w = kGroupLanes / 2; w >= 1; w /= 2) all.extend(cwbvhShflXorBox(groupMask, all, w));
  Vec3 offset{0.0f, 0.0f, 0.0f};
  if (has) cwbvhAddCentreOffset(mine.box, all.center(), all.extent(), offset);
  const uint32_t mySlot = assignSlotLanes(offset, n, member, groupMask);
  // By slot: member s takes the child whose slot is s.
  uint32_t source = kGroupLanes;
#pragma unroll
  for (uint32_t c = 0; c < kGroupLanes; ++c)
    if (c < n && fromLane(groupMask, mySlot, c) == member) source = c;
  const uint32_t from = source & (kGroupLanes - 1u);
  out.occupied = source < kGroupLanes;
  out.child.ref = fromLane(groupMask, mine.ref, from);
  out.child.count = fromLane(groupMask, mine.count, from);
  out.child.box = cwbvhShflBox(groupMask, mine.box, from);
  return true;
}

// cwbvhWriteNode by the members of the group: member s writes slot s's meta byte, its start
// reference (interior) or its triangle ids (leaf), and its planes; member 0 the bases and the
// triangle count.
// The grid exponents take the whole warp (cwbvhGridLanes): every lane must call it, `valid` false
// for lanes of groups without a node.
__device__ void writeNodeLanes(const BinaryTreeView& t, const SlotChild& mine, bool valid, uint32_t self,
                               uint32_t childBase, uint32_t triBase, uint32_t member, const CwbvhConvertOutput& out) {
  const bool isInterior = valid && mine.occupied && !isLeafRef(mine.child.ref);
  const bool isLeaf = valid && mine.occupied && isLeafRef(mine.child.ref);
  const uint32_t occupied = (__ballot_sync(0xffffffffu, valid && mine.occupied) >> cwbvhGroupFirstLane()) & 0xffu;
  const uint32_t interiorSlots = (__ballot_sync(0xffffffffu, isInterior) >> cwbvhGroupFirstLane()) & 0xffu;
  // Leaf triangles of the lower slots: an inclusive scan over the group, minus this lane's own.
  const uint32_t count = isLeaf ? mine.child.count : 0u;
  uint32_t below = count;
#pragma unroll
  for (uint32_t w = 1; w < kGroupLanes; w *= 2) {
    const uint32_t other = __shfl_up_sync(0xffffffffu, below, w, int(kGroupLanes));
    if (member >= w) below += other;
  }
  const uint32_t total = __shfl_sync(0xffffffffu, below, int(kGroupLanes - 1u), int(kGroupLanes));
  below -= count;
  const CwbvhLaneGrid g = cwbvhGridLanes(member, mine.child.box, occupied);
  if (!valid) return;
  CwbvhNode* node = out.nodes + self;
  cwbvhStoreGridLanes(node, member, !mine.occupied, mine.child.box, g);
  uint8_t meta = 0;
  if (isInterior) {
    meta = kCwbvhInterior;
    out.starts[childBase + uint32_t(__popc(interiorSlots & ((1u << member) - 1u)))] = mine.child.ref;
  } else if (isLeaf) {
    meta = uint8_t(kCwbvhLeaf | below);
    cwbvhCopyLeafTriangles(t, mine.child.ref, count, out.triIndex + triBase + below);
  }
  node->meta[member] = meta;
  if (member == 0) {
    node->triCount = uint8_t(total);
    node->childBase = childBase;
    node->triBase = triBase;
  }
}

// Level by level: round after round of gridDim.x * kGroupsPerBlock wide nodes, each opened by a
// group of 8 lanes, and the level's running prefix sums of (interior children, leaf triangles) in
// node order give its childBase and triBase. The sums are a block scan plus the sums of the lower
// blocks, which every block reads from blockSums after the barrier, so every block also knows the
// round's totals without another barrier.
__global__ void __launch_bounds__(kConvertBlock) cwbvhConvertKernel(ConvertParams p) {
  using BlockScan = cub::BlockScan<uint32_t, kConvertBlock>;
  __shared__ typename BlockScan::TempStorage scanStorage;
  __shared__ uint32_t sums[4];  // lower blocks' nodes and triangles, the round's nodes and triangles
  const RootInfo root = *p.root;
  const uint32_t perRound = gridDim.x * kGroupsPerBlock;
  const uint32_t lane = threadIdx.x & 31u, member = threadIdx.x % kGroupLanes;
  const uint32_t groupMask = 0xffu << cwbvhGroupFirstLane();
  uint32_t begin = 0, end = 1, nodes = 1, tris = 0, parity = 0, levels = 0;
  bool failed = false;
  while (begin < end) {
    ++levels;
    for (uint32_t roundBase = begin; roundBase < end; roundBase += perRound) {
      const uint32_t item = roundBase + blockIdx.x * kGroupsPerBlock + threadIdx.x / kGroupLanes;
      SlotChild mine;
      uint32_t interior = 0, triangles = 0;
      bool valid = item < end;
      if (valid) {
        const int32_t start = item == 0 ? root.ref : __ldcg(p.out.starts + item);
        if (!openNodeLanes(p.tree, start, item == 0 ? root.count : 0u, root.box, p.mergeLimit, member, groupMask, mine,
                           interior, triangles)) {
          failed = true;
          valid = false;
        }
      }
      // One entry per node (its lane 0); interior <= 8 and triangles <= 64 per node: a block's
      // sums fit 16 bits each.
      const uint32_t packed = valid && member == 0 ? (interior << 16) | triangles : 0u;
      uint32_t prefix = 0, blockTotal = 0;
      BlockScan(scanStorage).ExclusiveSum(packed, prefix, blockTotal);
      prefix = __shfl_sync(0xffffffffu, prefix, int(cwbvhGroupFirstLane()));
      if (threadIdx.x == 0) p.blockSums[parity * gridDim.x + blockIdx.x] = make_uint2(blockTotal >> 16, blockTotal & 0xffffu);
      if (threadIdx.x < 4) sums[threadIdx.x] = 0;
      gridBarrier(p.words);

      uint32_t v[4] = {0, 0, 0, 0};
      for (uint32_t b = threadIdx.x; b < gridDim.x; b += kConvertBlock) {
        const uint2 s = __ldcg(p.blockSums + parity * gridDim.x + b);
        if (b < blockIdx.x) v[0] += s.x, v[1] += s.y;
        v[2] += s.x, v[3] += s.y;
      }
#pragma unroll
      for (int k = 0; k < 4; ++k) {
        v[k] = warpSum(v[k]);
        if (lane == 0 && v[k] != 0) atomicAdd(&sums[k], v[k]);
      }
      __syncthreads();
      const uint32_t childBase = nodes + sums[0] + (prefix >> 16);
      const uint32_t triBase = tris + sums[1] + (prefix & 0xffffu);
      if (valid && (uint64_t(childBase) + interior > p.maxNodes || uint64_t(triBase) + triangles > p.tree.triangles)) {
        failed = true;  // the references form no tree over the triangles (the same in every lane of the group)
        valid = false;
      }
      writeNodeLanes(p.tree, mine, valid, item, childBase, triBase, member, p.out);
      nodes += sums[2];
      tris += sums[3];
      parity ^= 1u;
      __syncthreads();  // sums and scanStorage are rewritten by the next round
    }
    gridBarrier(p.words);  // the next level's starts are written
    begin = end;
    end = nodes;
    if (nodes > p.maxNodes) break;  // the same decision in every block
  }
  if (failed) atomicExch(p.words + kErrorWord, 1u);
  if (blockIdx.x == 0 && threadIdx.x == 0) {
    p.words[kNodeCountWord] = nodes;
    p.words[kLevelsWord] = levels;
    if (tris != p.tree.triangles || nodes > p.maxNodes) atomicExch(p.words + kErrorWord, 1u);
  }
}

}  // namespace

GpuCwbvhConverter::GpuCwbvhConverter(uint32_t triangles) : n_(triangles) {
  if (n_ == 0) throw tsah::DataError("GPU wide conversion: no triangles");
  // Every wide node but a one-leaf root starts at its own binary interior node (<= n - 1).
  const std::size_t maxNodes = std::max<std::size_t>(1, std::size_t(n_) - 1);
  nodes_.resize(maxNodes);
  starts_.resize(maxNodes);
  triIndex_.resize(n_);
  words_.resize(kConvertWords);
  // All blocks must be resident (the grid barrier), and fewer blocks make each barrier cheaper: a
  // small tree gets about one group of 8 lanes per 8 triangles (a wide node holds ~8 or more; wider
  // levels just take more rounds).
  blocks_ = std::min(residentBlocks(cwbvhConvertKernel, kConvertBlock, kConvertBlocksPerSm),
                     int(gridFor(std::size_t(n_ / 8) * kGroupLanes, kConvertBlock)));
  blockSums_.resize(2 * std::size_t(blocks_));
}

void GpuCwbvhConverter::enqueue(const GpuBvhNode* nodes, uint32_t nodeCount, const uint32_t* slotTri,
                                const RootInfo* root, uint32_t mergeLimit, cudaStream_t stream) {
  if (mergeLimit > kCwbvhMaxLeafTriangles)
    throw tsah::ConfigError("GPU wide conversion: leaves merge at most " + std::to_string(kCwbvhMaxLeafTriangles) +
                            " triangles");
  words_.fillBytes(0, stream);
  ConvertParams p{{nodes, nodeCount, slotTri, n_},
                  root,
                  {nodes_.data(), starts_.data(), triIndex_.data(), nullptr, nullptr},
                  blockSums_.data(),
                  words_.data(),
                  mergeLimit,
                  uint32_t(nodes_.size())};
  cwbvhConvertKernel<<<unsigned(blocks_), kConvertBlock, 0, stream>>>(p);
  CUDA_CHECK_LAUNCH("cwbvhConvertKernel");
}

uint32_t GpuCwbvhConverter::collect(cudaStream_t stream) {
  const std::vector<uint32_t> words = words_.download(stream);
  if (words[kErrorWord] != 0)
    throw tsah::Failure(
        "GPU wide conversion: the rebuilt tree is invalid or a wide node's leaves would hold more "
        "than 64 triangles");
  nodeCount_ = words[kNodeCountWord];
  levels_ = words[kLevelsWord];
  return nodeCount_;
}

CwbvhTree GpuCwbvhConverter::download(cudaStream_t stream) const {
  CwbvhTree t;
  t.nodes = nodes_.download(stream, nodeCount_);
  t.triIndex = triIndex_.download(stream);
  t.rootRef = 0;
  t.rootCount = 0;
  return t;
}

}  // namespace tsah::cuda::detail
