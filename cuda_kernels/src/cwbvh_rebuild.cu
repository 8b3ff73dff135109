// The conversion of a rebuilt binary tree into the compressed 8-wide layout (see
// cwbvh_rebuild.hpp). One persistent kernel: all its blocks are resident at once (occupancy
// calculator, as the HLBVH-SAH cluster builder), so a software grid barrier separates the steps
// of a level; the number of levels is never known on the host, which keeps the work capturable.
#include <cub/block/block_scan.cuh>
#include <cuda/atomic>

#include <algorithm>
#include <string>

#include "anim/error.hpp"
#include "cwbvh_rebuild.hpp"
#include "launch.hpp"

namespace tsah::cuda::detail {

namespace {

constexpr int kConvertBlock = 128;
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

// Level by level: round after round of gridDim.x * kConvertBlock wide nodes, each thread opens
// one node (cwbvhOpen) and the level's running prefix sums of (interior children, leaf
// triangles) in node order give its childBase and triBase. The sums are a block scan plus the
// sums of the lower blocks, which every block reads from blockSums after the barrier, so every
// block also knows the round's totals without another barrier.
__global__ void __launch_bounds__(kConvertBlock) cwbvhConvertKernel(ConvertParams p) {
  using BlockScan = cub::BlockScan<uint32_t, kConvertBlock>;
  __shared__ typename BlockScan::TempStorage scanStorage;
  __shared__ uint32_t sums[4];  // lower blocks' nodes and triangles, the round's nodes and triangles
  const RootInfo root = *p.root;
  const uint32_t perRound = gridDim.x * kConvertBlock;
  const uint32_t lane = threadIdx.x & 31u;
  uint32_t begin = 0, end = 1, nodes = 1, tris = 0, parity = 0, levels = 0;
  bool failed = false;
  while (begin < end) {
    ++levels;
    for (uint32_t roundBase = begin; roundBase < end; roundBase += perRound) {
      const uint32_t item = roundBase + blockIdx.x * kConvertBlock + threadIdx.x;
      CwbvhOpening o;
      bool valid = item < end;
      if (valid) {
        const int32_t start = item == 0 ? root.ref : __ldcg(p.out.starts + item);
        if (!cwbvhOpen(p.tree, start, item == 0 ? root.count : 0u, root.box, p.mergeLimit, o)) {
          failed = true;
          valid = false;
        }
      }
      // interior <= 8 and triangles <= 64 per node: a block's sums fit 16 bits each.
      const uint32_t packed = valid ? (o.interior << 16) | o.triangles : 0u;
      uint32_t prefix = 0, blockTotal = 0;
      BlockScan(scanStorage).ExclusiveSum(packed, prefix, blockTotal);
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
      if (valid) {
        const uint32_t childBase = nodes + sums[0] + (prefix >> 16);
        const uint32_t triBase = tris + sums[1] + (prefix & 0xffffu);
        if (uint64_t(childBase) + o.interior > p.maxNodes || uint64_t(triBase) + o.triangles > p.tree.triangles)
          failed = true;  // the references form no tree over the triangles
        else
          cwbvhWriteNode(p.tree, o, item, childBase, triBase, p.out);
      }
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
  if (n_ == 0) throw anim::Error("GPU wide conversion: no triangles");
  // Every wide node but a one-leaf root starts at its own binary interior node (<= n - 1).
  const std::size_t maxNodes = std::max<std::size_t>(1, std::size_t(n_) - 1);
  nodes_.resize(maxNodes);
  starts_.resize(maxNodes);
  triIndex_.resize(n_);
  words_.resize(kConvertWords);
  // All blocks must be resident (the grid barrier); two per multiprocessor are enough threads for
  // the widest levels, and fewer blocks make each barrier cheaper: a small tree gets about one
  // thread per 8 triangles (a wide node holds ~8 or more; wider levels just take more rounds).
  blocks_ = std::min(residentBlocks(cwbvhConvertKernel, kConvertBlock, 2), int(gridFor(n_ / 8, kConvertBlock)));
  blockSums_.resize(2 * std::size_t(blocks_));
}

void GpuCwbvhConverter::enqueue(const GpuBvhNode* nodes, uint32_t nodeCount, const uint32_t* slotTri,
                                const RootInfo* root, uint32_t mergeLimit, cudaStream_t stream) {
  if (mergeLimit > kCwbvhMaxLeafTriangles)
    throw anim::Error("GPU wide conversion: leaves merge at most " + std::to_string(kCwbvhMaxLeafTriangles) +
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
    throw anim::Error("GPU wide conversion: the rebuilt tree is invalid or a wide node's leaves would hold more "
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
