// The two-level runtime's kernels: instance world boxes, the TLAS refit over them, and the trace
// of rays through instances (two_level_traversal.cuh), packed or in the caller's arrays.
// Compiled with -fmad=false (see CMakeLists.txt): boxes and hits round as on the CPU.
#include "launch.hpp"
#include "ray_arrays.cuh"
#include "refit_walk.cuh"
#include "triangle_boxes.cuh"
#include "two_level_traversal.cuh"
#include "woop_block.cuh"
#include "tsah/core/instance_transform.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda::detail {

namespace {

__global__ void instanceBoxesKernel(const InstanceState* __restrict__ instances, const BlasView* __restrict__ views,
                                    uint32_t count, Aabb* __restrict__ boxes) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const InstanceState& inst = instances[i];
  boxes[i] = transformBoxRows(views[inst.view].root->box, inst.world);
}

// 16 bytes a thread when both ends are 16-byte aligned, and what is left (the last bytes, or all of
// them when unaligned) a byte a thread.
__global__ void copyFromHostKernel(uint8_t* __restrict__ device, const uint8_t* __restrict__ host, std::size_t bytes) {
  const std::size_t i = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const bool aligned = (reinterpret_cast<uintptr_t>(device) | reinterpret_cast<uintptr_t>(host)) % 16 == 0;
  const std::size_t words = aligned ? bytes / 16 : 0;
  if (i < words) reinterpret_cast<uint4*>(device)[i] = reinterpret_cast<const uint4*>(host)[i];
  const std::size_t first = 16 * words, threads = std::size_t(gridDim.x) * blockDim.x;
  for (std::size_t b = first + i; b < bytes; b += threads) device[b] = host[b];
}

// The flat runtime's refit walk with instance boxes as the leaves' content.
__global__ void tlasRefitKernel(GpuBvhNode* __restrict__ nodes, const uint32_t* __restrict__ nodeParent,
                                const LeafRecord* __restrict__ leaves, uint32_t leafCount,
                                const uint32_t* __restrict__ triIndex, const Aabb* __restrict__ instanceBoxes,
                                uint32_t* __restrict__ counters, RootInfo* __restrict__ root) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= leafCount) return;
  const LeafRecord leaf = leaves[i];
  Aabb box;
  for (uint32_t s = leaf.first; s < leaf.first + leaf.count; ++s) box.extend(instanceBoxes[triIndex[s]]);
  refitUpwards(nodes, nodeParent, leaf.parentSlot, box, counters, root);
}

// Block refits: threads per part of a pose's tree, and for the TLAS (one block for the whole
// frame's instances).
constexpr uint32_t kPartThreads = 256;
constexpr uint32_t kTlasBlockThreads = 1024;

// The Woop triangles of the top's leaf items (scattered slots: one thread per leaf).
__device__ void topLeafWoop(const RefitPartsView& view, const RefitPart& part, const uint32_t* __restrict__ slotVertices,
                            const float* __restrict__ positions, WoopTriangle* __restrict__ woop) {
  for (uint32_t i = threadIdx.x; i < part.itemCount; i += blockDim.x) {
    const RefitPartItem item = view.items[part.firstItem + i];
    if (item.count == kPartEntry) continue;
    for (uint32_t s = item.first; s < item.first + item.count; ++s) {
      const uint32_t* tri = slotVertices + 3 * std::size_t(s);
      woop[s] = makeWoopTriangle(loadVertex(positions, __ldg(tri)), loadVertex(positions, __ldg(tri + 1)),
                                 loadVertex(positions, __ldg(tri + 2)));
    }
  }
}

// A subtree part's triangles, one thread per slot (consecutive threads, consecutive slots: the
// loads of the vertex ids and the Woop stores coalesce): each slot's Woop triangle, and its box in
// shared memory (triBoxes: 6 floats per slot of the part) for the leaves' boxes.
__device__ void partTriangles(const RefitPart& part, const uint32_t* __restrict__ slotVertices,
                              const float* __restrict__ positions, WoopTriangle* __restrict__ woop, float* triBoxes) {
  for (uint32_t i = threadIdx.x; i < part.slotCount; i += blockDim.x) {
    const uint32_t s = part.firstSlot + i;
    const uint32_t* tri = slotVertices + 3 * std::size_t(s);
    const Vec3 v0 = loadVertex(positions, __ldg(tri)), v1 = loadVertex(positions, __ldg(tri + 1)),
               v2 = loadVertex(positions, __ldg(tri + 2));
    woop[s] = makeWoopTriangle(v0, v1, v2);
    Aabb box;
    box.extend(v0);
    box.extend(v1);
    box.extend(v2);
    float* b = triBoxes + 6 * std::size_t(i);
    b[0] = box.lo.x, b[1] = box.lo.y, b[2] = box.lo.z, b[3] = box.hi.x, b[4] = box.hi.y, b[5] = box.hi.z;
  }
}

// Block (pose b = blockIdx.x, subtree part blockIdx.y): the part's triangles and refit. The last of
// a pose's subtree blocks to finish (counted in tickets[b], cleared again for the next frame)
// refits the top over the subtrees' root boxes (partBoxes) and its own leaves.
// Four blocks per multiprocessor (at most 64 registers a thread): a frame's blocks of town's 24
// horses (22 parts each) run in one wave.
__global__ void __launch_bounds__(kPartThreads, 4)
    posePartsKernel(GpuBvhNode* __restrict__ nodes, RefitPartsView view, const uint32_t* __restrict__ slotVertices,
                    const float* __restrict__ positions, WoopTriangle* __restrict__ woop,
                    RootInfo* __restrict__ roots, Aabb* partBoxes, uint32_t* tickets, BatchStrides batch,
                    const FrameParams* __restrict__ frames) {
  extern __shared__ uint32_t shared[];
  __shared__ bool lastBlock;
  const uint32_t b = blockIdx.x;
  if (frames[b].held) return;  // every block of a held pose: its tickets stay zero
  const float* own = positions + b * batch.positions;
  GpuBvhNode* ownNodes = nodes + b * batch.nodes;
  WoopTriangle* ownWoop = woop + b * batch.woop;
  Aabb* ownPartBoxes = partBoxes + std::size_t(b) * view.subtreeCount;
  const RefitPart part = view.parts[blockIdx.y];
  float* triBoxes = reinterpret_cast<float*>(shared + partWalkWords(part.nodeCount));
  const auto triangles = [&] { partTriangles(part, slotVertices, own, ownWoop, triBoxes); };
  const auto leafBoxOf = [&](const RefitPartItem& item) {
    Aabb box;
    for (uint32_t s = item.first - part.firstSlot; s < item.first - part.firstSlot + item.count; ++s) {
      const float* t = triBoxes + 6 * std::size_t(s);
      box.extend(Aabb{{t[0], t[1], t[2]}, {t[3], t[4], t[5]}});
    }
    return box;
  };
  partRefit(ownNodes, view, part, triangles, leafBoxOf, view.hasTop ? ownPartBoxes + blockIdx.y : &roots[b].box,
            shared);
  if (!view.hasTop) return;
  __threadfence();  // this part's root box before the ticket
  __syncthreads();
  if (threadIdx.x == 0) lastBlock = atomicAdd(tickets + b, 1u) == view.subtreeCount - 1;
  __syncthreads();
  if (!lastBlock) return;
  __threadfence();
  const RefitPart top = view.parts[view.subtreeCount];
  const auto topBoxOf = [&](const RefitPartItem& item) {
    if (item.count != kPartEntry) return leafBox(item.first, item.count, slotVertices, own);
    // Written by other blocks of this launch: read through L2.
    const float* f = reinterpret_cast<const float*>(ownPartBoxes + item.first);
    return Aabb{{__ldcg(f), __ldcg(f + 1), __ldcg(f + 2)}, {__ldcg(f + 3), __ldcg(f + 4), __ldcg(f + 5)}};
  };
  partRefit(ownNodes, view, top, [] {}, topBoxOf, &roots[b].box, shared);
  topLeafWoop(view, top, slotVertices, own, ownWoop);
  if (threadIdx.x == 0) tickets[b] = 0;
}

// One block: every instance's world box, then the TLAS refit over them (the TLAS is one part).
__global__ void __launch_bounds__(kTlasBlockThreads)
    tlasBlockKernel(const InstanceState* __restrict__ instances, const BlasView* __restrict__ views, uint32_t count,
                    Aabb* instanceBoxes, GpuBvhNode* __restrict__ nodes, RefitPartsView tlasParts,
                    const uint32_t* __restrict__ triIndex, RootInfo* __restrict__ root) {
  extern __shared__ uint32_t shared[];
  for (uint32_t i = threadIdx.x; i < count; i += blockDim.x)
    instanceBoxes[i] = transformBoxRows(views[instances[i].view].root->box, instances[i].world);
  __syncthreads();  // the boxes of other threads, read below (plain loads: written in this launch)
  const auto boxOf = [&](const RefitPartItem& item) {
    Aabb box;
    for (uint32_t s = item.first; s < item.first + item.count; ++s) box.extend(instanceBoxes[triIndex[s]]);
    return box;
  };
  partRefit(nodes, tlasParts, tlasParts.parts[0], [] {}, boxOf, &root->box, shared);
}

// anim::Animation::positionsAt's blend of one coordinate (and the interpolation kernels'): beta * a +
// alpha * b with both weights >= 0, so the result never decreases when a or b grows (each rounded
// product and the rounded sum are monotone): a bound blended like a coordinate bounds it.
__device__ __forceinline__ float blendKeys(float a, float b, const FrameParams& f, float beta) {
  // alpha == 0: positionsAt copies the keyframe (1 * x + 0 * y would turn -0 into +0).
  return f.alpha == 0.0f ? a : __fadd_rn(__fmul_rn(beta, a), __fmul_rn(f.alpha, b));
}

// One axis of a box, [lo, hi], blended from two keyframes' bounds. A source with static vertices
// (padStatic) pads it: a static vertex keeps its rest coordinate s exactly, while the blend of two
// bounds equal to s may round up to 3 * 2^-24 * |s| away from it (beta = 1 - alpha rounds, then
// two products and a sum). |s| <= m, the largest bound's magnitude, so 2^-22 * m (plus the
// smallest normal for underflowing products) covers it. At a keyframe (alpha = 0) the blend copies
// the bounds: no pad. An empty axis (lo > hi) stays as it is.
__device__ __forceinline__ float2 blendAxis(float loA, float hiA, float loB, float hiB, const FrameParams& f,
                                            float beta, bool padStatic) {
  float lo = blendKeys(loA, loB, f, beta), hi = blendKeys(hiA, hiB, f, beta);
  if (padStatic && f.alpha != 0.0f && lo <= hi) {
    const float m = fmaxf(fmaxf(fabsf(loA), fabsf(hiA)), fmaxf(fabsf(loB), fabsf(hiB)));
    const float pad = __fadd_ru(__fmul_ru(m, 0x1p-22f), 0x1p-126f);
    lo = __fsub_rd(lo, pad);
    hi = __fadd_ru(hi, pad);
  }
  return make_float2(lo, hi);
}

// Four box floats of a node, two axes' (lo, hi) pairs (gpu_layout.hpp: n0xy, n1xy, nz).
__device__ __forceinline__ float4 blendNodeFloats(const float4& a, const float4& b, const FrameParams& f, float beta,
                                                  bool padStatic) {
  const float2 first = blendAxis(a.x, a.y, b.x, b.y, f, beta, padStatic);
  const float2 second = blendAxis(a.z, a.w, b.z, b.w, f, beta, padStatic);
  return make_float4(first.x, first.y, second.x, second.y);
}

// Pose b = blockIdx.y; the blocks along x do, in this order, the interpolation of its moving
// coordinates (one a thread), its Woop triangles (woopBlock, each vertex blended from the
// keyframes as the interpolation blends it: no wait for the interpolation's stores) and its boxes
// (a third of a node's twelve box floats a thread, then the root box).
__global__ void __launch_bounds__(kWoopBlock)
    keyedPoseKernel(KeyedSource src, const FrameParams* __restrict__ frames, float* positions,
                    GpuBvhNode* __restrict__ nodes, WoopTriangle* __restrict__ woop, RootInfo* __restrict__ roots,
                    BatchStrides batch, uint32_t interpolationBlocks, uint32_t woopBlocks) {
  const uint32_t b = blockIdx.y;
  const FrameParams f = frames[b];
  if (f.held) return;
  const float beta = 1.0f - f.alpha;
  const float* keyA = src.keyframes + f.a;
  const float* keyB = src.keyframes + f.b;
  float* own = positions + b * batch.positions;
  uint32_t block = blockIdx.x;
  if (block < interpolationBlocks) {
    const std::size_t i = std::size_t(block) * kWoopBlock + threadIdx.x;
    if (i >= 3 * std::size_t(src.movingCount)) return;
    const std::size_t dst = src.movingIds ? 3 * std::size_t(__ldg(src.movingIds + i / 3)) + i % 3 : i;
    own[dst] = blendKeys(__ldg(keyA + i), __ldg(keyB + i), f, beta);
    return;
  }
  block -= interpolationBlocks;
  if (block < woopBlocks) {
    const auto vertices = [&](uint32_t s, Vec3* v) {
      const uint32_t* tri = src.slotVertices + 3 * std::size_t(s);
#pragma unroll
      for (int k = 0; k < 3; ++k) {
        const uint32_t id = __ldg(tri + k);
        const uint32_t m = src.movingIndex ? __ldg(src.movingIndex + id) : id;
        if (m == kStaticVertex) {  // its rest position, which no frame writes
          const float* p = own + 3 * std::size_t(id);
          v[k] = {p[0], p[1], p[2]};
          continue;
        }
        const std::size_t c = 3 * std::size_t(m);
        v[k] = {blendKeys(__ldg(keyA + c), __ldg(keyB + c), f, beta),
                blendKeys(__ldg(keyA + c + 1), __ldg(keyB + c + 1), f, beta),
                blendKeys(__ldg(keyA + c + 2), __ldg(keyB + c + 2), f, beta)};
      }
    };
    woopBlock(block * kWoopBlock, src.slots, vertices, woop + b * batch.woop);
    return;
  }
  block -= woopBlocks;
  const bool padStatic = src.movingIndex != nullptr;  // some vertex is static
  const uint32_t j = block * kWoopBlock + threadIdx.x;
  const uint32_t n = src.nodeCount;
  if (j < 3 * n) {  // float4 j % 3 of node j / 3: its twelve box floats, each a lower or an upper bound
    const float4 a = reinterpret_cast<const float4*>(src.keyNodes + std::size_t(f.keyA) * n + j / 3)[j % 3];
    const float4 c = reinterpret_cast<const float4*>(src.keyNodes + std::size_t(f.keyB) * n + j / 3)[j % 3];
    reinterpret_cast<float4*>(nodes + b * batch.nodes + j / 3)[j % 3] =
        blendNodeFloats(a, c, f, beta, padStatic);
  } else if (j == 3 * n) {
    const Aabb a = src.keyRoots[f.keyA].box, c = src.keyRoots[f.keyB].box;
    const float2 x = blendAxis(a.lo.x, a.hi.x, c.lo.x, c.hi.x, f, beta, padStatic);
    const float2 y = blendAxis(a.lo.y, a.hi.y, c.lo.y, c.hi.y, f, beta, padStatic);
    const float2 z = blendAxis(a.lo.z, a.hi.z, c.lo.z, c.hi.z, f, beta, padStatic);
    roots[b].box = Aabb{{x.x, y.x, z.x}, {x.y, y.y, z.y}};
  }
}

// Rays: const Ray* or ArrayRays; Hits: InstanceHit* or ArrayInstanceHits (ray_arrays.cuh). One
// kernel per BLAS layout: each is compiled for its own BLAS loop.
template <bool AnyHit, BlasForm Form, class Rays, class Hits>
__global__ void __launch_bounds__(128) twoLevelTraceKernel(TlasScene scene, Rays rays, uint32_t count, Hits hits,
                                                           uint8_t* __restrict__ occluded) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const Ray ray = loadRay(rays, i);
  if constexpr (AnyHit)
    occluded[i] = twoLevelAnyHit<Form>(scene, ray) ? 1 : 0;
  else
    storeInstanceHit(hits, i, twoLevelClosestHit<Form>(scene, ray));
}

template <BlasForm Form, class Rays, class Hits>
void launchTraceOfForm(const TlasScene& scene, const Rays& rays, uint32_t count, const Hits& hits, uint8_t* occluded,
                       cudaStream_t stream) {
  const unsigned block = 128;  // fixed by __launch_bounds__
  if (occluded)
    twoLevelTraceKernel<true, Form, Rays, Hits>
        <<<gridFor(count, block), block, 0, stream>>>(scene, rays, count, hits, occluded);
  else
    twoLevelTraceKernel<false, Form, Rays, Hits>
        <<<gridFor(count, block), block, 0, stream>>>(scene, rays, count, hits, occluded);
  CUDA_CHECK_LAUNCH("twoLevelTraceKernel");
}

template <class Rays, class Hits>
void launchTraceOf(const TlasScene& scene, const Rays& rays, uint32_t count, const Hits& hits, uint8_t* occluded,
                   cudaStream_t stream) {
  if (count == 0) return;
  if (scene.compressedBlas)
    launchTraceOfForm<BlasForm::Compressed>(scene, rays, count, hits, occluded, stream);
  else
    launchTraceOfForm<BlasForm::Binary>(scene, rays, count, hits, occluded, stream);
}

}  // namespace

void launchCopyFromHost(void* device, const void* mappedHost, std::size_t bytes, cudaStream_t stream) {
  if (bytes == 0) return;
  const unsigned block = 256;
  const std::size_t threads = (bytes + 15) / 16;  // the kernel's byte loop strides over the grid
  copyFromHostKernel<<<unsigned((threads + block - 1) / block), block, 0, stream>>>(
      static_cast<uint8_t*>(device), static_cast<const uint8_t*>(mappedHost), bytes);
  CUDA_CHECK_LAUNCH("copyFromHostKernel");
}

void launchInstanceBoxes(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* boxes,
                         cudaStream_t stream) {
  if (count == 0) return;
  const unsigned block = 128;
  instanceBoxesKernel<<<gridFor(count, block), block, 0, stream>>>(instances, views, count, boxes);
  CUDA_CHECK_LAUNCH("instanceBoxesKernel");
}

void launchTlasRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                     const uint32_t* triIndex, const Aabb* instanceBoxes, uint32_t* counters, RootInfo* root,
                     cudaStream_t stream) {
  if (leafCount == 0) return;
  const unsigned block = 128;
  tlasRefitKernel<<<gridFor(leafCount, block), block, 0, stream>>>(nodes, nodeParent, leaves, leafCount, triIndex,
                                                                   instanceBoxes, counters, root);
  CUDA_CHECK_LAUNCH("tlasRefitKernel");
}

uint64_t prepareBlockRefits() {
  int device = 0, optIn = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  CUDA_CHECK(cudaDeviceGetAttribute(&optIn, cudaDevAttrMaxSharedMemoryPerBlockOptin, device));
  // Each kernel's static shared memory counts against the same limit.
  const int dynamicLimit = optIn - 64;
  CUDA_CHECK(cudaFuncSetAttribute(posePartsKernel, cudaFuncAttributeMaxDynamicSharedMemorySize, dynamicLimit));
  CUDA_CHECK(cudaFuncSetAttribute(tlasBlockKernel, cudaFuncAttributeMaxDynamicSharedMemorySize, dynamicLimit));
  return uint64_t(dynamicLimit);
}

void launchPoseBlasParts(GpuBvhNode* nodes, const RefitPartsView& parts, uint64_t sharedBytes,
                         const uint32_t* slotVertices, const float* positions, WoopTriangle* woop, RootInfo* roots,
                         Aabb* partBoxes, uint32_t* tickets, uint32_t poseCount, const BatchStrides& batch,
                         const FrameParams* frames, cudaStream_t stream) {
  if (poseCount == 0) return;
  const dim3 grid(poseCount, parts.subtreeCount);
  posePartsKernel<<<grid, kPartThreads, sharedBytes, stream>>>(
      nodes, parts, slotVertices, positions, woop, roots, partBoxes, tickets, batch, frames);
  CUDA_CHECK_LAUNCH("posePartsKernel");
}

void launchKeyedPoses(const KeyedSource& source, const FrameParams* frames, float* positions, GpuBvhNode* nodes,
                      WoopTriangle* woop, RootInfo* roots, uint32_t poseCount, const BatchStrides& batch,
                      cudaStream_t stream) {
  const auto blocksFor = [](std::size_t n) { return uint32_t((n + kWoopBlock - 1) / kWoopBlock); };
  const uint32_t interpolationBlocks = blocksFor(3 * std::size_t(source.movingCount));
  const uint32_t woopBlocks = blocksFor(source.slots);
  const uint32_t blocks = interpolationBlocks + woopBlocks + blocksFor(3 * std::size_t(source.nodeCount) + 1);
  forEachBatchChunk(poseCount, [&](uint32_t first, uint32_t count) {
    keyedPoseKernel<<<dim3(blocks, count), kWoopBlock, 0, stream>>>(
        source, frames + first, positions + first * batch.positions, nodes + first * batch.nodes,
        woop + first * batch.woop, roots + first, batch, interpolationBlocks, woopBlocks);
    CUDA_CHECK_LAUNCH("keyedPoseKernel");
  });
}

void launchTlasBlock(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* instanceBoxes,
                     GpuBvhNode* nodes, const RefitPartsView& tlasParts, uint32_t tlasNodeCount,
                     const uint32_t* triIndex, RootInfo* root, cudaStream_t stream) {
  if (count == 0) return;
  tlasBlockKernel<<<1, kTlasBlockThreads, partRefitBytes(tlasNodeCount), stream>>>(
      instances, views, count, instanceBoxes, nodes, tlasParts, triIndex, root);
  CUDA_CHECK_LAUNCH("tlasBlockKernel");
}

void launchTwoLevelTrace(const TlasScene& scene, const Ray* rays, uint32_t count, InstanceHit* hits, uint8_t* occluded,
                         cudaStream_t stream) {
  launchTraceOf(scene, rays, count, hits, occluded, stream);
}

void launchTwoLevelArrayTrace(const TlasScene& scene, const ArrayRays& rays, const ArrayInstanceHits& hits,
                              uint8_t* occluded, cudaStream_t stream) {
  launchTraceOf(scene, rays, rays.count, hits, occluded, stream);
}

}  // namespace tsah::cuda::detail
