#pragma once
// The two-level runtime's device data and kernels (two_level_kernels.cu); no CUDA syntax here, so
// the C++ compiler reads it too.
#include <cuda_runtime_api.h>

#include <cstdint>
#include <type_traits>

#include "device_arrays.hpp"
#include "device_types.hpp"
#include "tsah/core/aabb.hpp"
#include "tsah/core/instance_transform.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/cwbvh_layout.hpp"
#include "tsah/layout/gpu_layout.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah::cuda::detail {

// One traceable BLAS on the device: a static source's, or a pose's (its own nodes, positions and
// Woop triangles; triIndex and indices are its source's, shared). root holds ref, count and the
// box of this frame (written by the refit). In the compressed layout (GpuTwoLevelRuntime::Config::
// layout cwbvh) cwbvhNodes is set and nodes is null: woop and triIndex are per slot of that layout,
// root's ref and count its root's.
struct BlasView {
  const GpuBvhNode* nodes = nullptr;
  const WoopTriangle* woop = nullptr;
  const uint32_t* triIndex = nullptr;
  const uint32_t* indices = nullptr;
  const float* positions = nullptr;
  const RootInfo* root = nullptr;
  const CwbvhNode* cwbvhNodes = nullptr;
};

// A BLAS view in the compressed layout as its traversal reads it (root: *view.root).
TSAH_HD CwbvhView blasCwbvhView(const BlasView& view, const RootInfo& root) {
  CwbvhView v;
  v.nodes = view.cwbvhNodes;
  v.woop = view.woop;
  v.triIndex = view.triIndex;
  v.indices = view.indices;
  v.positions = view.positions;
  v.rootRef = root.ref;
  v.rootCount = root.count;
  v.rootBox = root.box;
  return v;
}

// A BLAS view as the binary traversal reads a tree.
TSAH_HD TraceScene blasTraceScene(const BlasView& view) {
  TraceScene blas;
  blas.nodes = view.nodes;
  blas.woop = view.woop;
  blas.triIndex = view.triIndex;
  blas.indices = view.indices;
  blas.positions = view.positions;
  blas.root = view.root;
  return blas;
}

// Per instance, written by the host each frame: world(t) in double (its box is transformed exactly
// as tsah::transformBox does), world -> instance in float (the CPU runtime's Affine3x4), the BLAS
// view it traces and whether world(t) is invertible (a singular instance is never hit).
struct InstanceState {
  double world[12];
  Affine3x4 toInstance;
  uint32_t view;
  uint32_t visible;
};
static_assert(std::is_trivially_copyable_v<InstanceState>);

// A hit of the two-level trace (tsah::TwoLevelHit's fields).
struct InstanceHit {
  float t, u, v;
  uint32_t instance, prim;
};

// Closest hits written into the caller's device arrays, one value per ray in each non-null array
// (a miss: t = +inf, u = v = 0, instance = triangle = kNoHit).
struct ArrayInstanceHits {
  float* t = nullptr;
  float* u = nullptr;
  float* v = nullptr;
  uint32_t* instance = nullptr;
  uint32_t* triangle = nullptr;  // the triangle of the instance's source
};

// The TLAS as the trace reads it.
struct TlasScene {
  const GpuBvhNode* nodes = nullptr;
  const uint32_t* triIndex = nullptr;  // slot -> instance
  const RootInfo* root = nullptr;
  const InstanceState* instances = nullptr;
  const BlasView* views = nullptr;
  const Aabb* instanceBoxes = nullptr;  // per instance: its world box this frame
  bool compressedBlas = false;          // every view in the compressed layout (the trace kernels' choice)
};

struct BlurredTlasScene;  // two_level_blur.hpp

// What the two-level renderer (two_level_render.cu) and the device-array queries read of a
// GpuTwoLevelRuntime: the trace scene of its current frame (of a blurred frame: the instant state at
// the close), the blurred frame's state (null when the frame is instant) and the stream its updates
// run on.
struct TwoLevelTraceAccess {
  TlasScene scene;
  const BlurredTlasScene* blurred = nullptr;
  cudaStream_t stream = nullptr;
};

// Per instance, its world box: its BLAS root box transformed by world(t), rounded outward
// (tsah::transformBox).
void launchInstanceBoxes(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* boxes,
                         cudaStream_t stream);
// `bytes` from pinned host memory (its device pointer, mapped) to device memory, by a kernel: in a
// CUDA graph a copy node costs about 10 us whatever its size, a kernel reading it over the bus about 3.
void launchCopyFromHost(void* device, const void* mappedHost, std::size_t bytes, cudaStream_t stream);
// Bottom-up refit of the TLAS from the instance boxes (counters zero on entry), root->box included.
void launchTlasRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                     const uint32_t* triIndex, const Aabb* instanceBoxes, uint32_t* counters, RootInfo* root,
                     cudaStream_t stream);
// Block refits (refit_walk.cuh's partRefit): usable when a part's partRefitBytes <= the bytes
// prepareBlockRefits returns (the device's opt-in shared memory per block, less
// the kernels' own; it lets the kernels use that much, on the current device).
uint64_t prepareBlockRefits();
// Every pose of a group (BatchStrides) refitted from its positions by the parts of its source's
// tree (one block per pose and subtree part; the top by the last of them), with its Woop
// triangles. sharedBytes: the most partRefitBytes(nodeCount, slotCount) of a part. partBoxes:
// subtreeCount boxes per pose; tickets: one per pose, zero on entry (and left zero). frames: per
// pose its frame; a held one (FrameParams::held) is left as it is.
void launchPoseBlasParts(GpuBvhNode* nodes, const RefitPartsView& parts, uint64_t sharedBytes,
                         const uint32_t* slotVertices, const float* positions, WoopTriangle* woop, RootInfo* roots,
                         Aabb* partBoxes, uint32_t* tickets, uint32_t poseCount, const BatchStrides& batch,
                         const FrameParams* frames, cudaStream_t stream);
// An animated source as the keyed pose update reads it: its keyframes (moving vertices only,
// keyframe-major), where each vertex's coordinates lie in a keyframe (movingIndex: per vertex, its
// rank among the moving ones or kStaticVertex; null when every vertex moves), its slots' vertex ids,
// and its tree refitted at every keyframe (keyNodes: nodeCount nodes per keyframe; keyRoots: one per
// keyframe).
inline constexpr uint32_t kStaticVertex = 0xffffffffu;
struct KeyedSource {
  const float* keyframes = nullptr;
  const uint32_t* movingIds = nullptr;
  const uint32_t* movingIndex = nullptr;
  uint32_t movingCount = 0;
  const uint32_t* slotVertices = nullptr;
  uint32_t slots = 0;
  const GpuBvhNode* keyNodes = nullptr;
  const RootInfo* keyRoots = nullptr;
  uint32_t nodeCount = 0;
};
// Every pose of a group (BatchStrides; pose b blends frames[b], a held one is left as it is) in one
// launch, without a refit: its moving vertices interpolated into its positions, its Woop triangles
// from the same interpolation (bit for bit the positions'), and every child box and the root box
// lerped from the two keyframes' boxes with the interpolation's weights and rounding. Each lerped
// bound is a monotone function of the two keyframes' bounds, so the lerped box holds the lerped
// vertices; a source with static vertices pads its lerped boxes by the blend's rounding of a static
// coordinate (docs/two-level.md).
void launchKeyedPoses(const KeyedSource& source, const FrameParams* frames, float* positions, GpuBvhNode* nodes,
                      WoopTriangle* woop, RootInfo* roots, uint32_t poseCount, const BatchStrides& batch,
                      cudaStream_t stream);
// launchInstanceBoxes and the TLAS refit in one block (tlasParts: the TLAS as one part of
// tlasNodeCount nodes).
void launchTlasBlock(const InstanceState* instances, const BlasView* views, uint32_t count, Aabb* instanceBoxes,
                     GpuBvhNode* nodes, const RefitPartsView& tlasParts, uint32_t tlasNodeCount,
                     const uint32_t* triIndex, RootInfo* root, cudaStream_t stream);
// One thread per ray: closest hits into hits, or (occluded non-null) any hits into occluded.
void launchTwoLevelTrace(const TlasScene& scene, const Ray* rays, uint32_t count, InstanceHit* hits,
                         uint8_t* occluded, cudaStream_t stream);
// The same for rays and results in the caller's arrays (device_arrays.hpp's ArrayRays).
void launchTwoLevelArrayTrace(const TlasScene& scene, const ArrayRays& rays, const ArrayInstanceHits& hits,
                              uint8_t* occluded, cudaStream_t stream);

}  // namespace tsah::cuda::detail
