#pragma once
// The blurred frame on the device (blurred_traversal.cu): its traversal layout, built from the key
// arrays after every key is refitted, and the trace of a ray buffer over it with the CPU runtime's
// lerps (tsah/layout/motion_blur.hpp), by the binary layout's device loop (bvh2_traversal.cuh).
#include <cstdint>
#include <cuda_runtime_api.h>

#include "device_types.hpp"
#include "tsah/layout/blurred_node.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah::cuda::detail {

// One slot's triangle at one key: its three vertices' positions at that key (v0 xyz, v1 xyz, v2 xyz)
// and three zeros, 48 bytes, so that a 16-byte aligned record is three vector loads.
struct alignas(16) KeyTriangle {
  float v[12];
};
static_assert(sizeof(KeyTriangle) == 48);

// The layout a blurred frame is traced from (docs/motion-blur.md#memory), key-adjacent so that a
// ray's segment (keys s and s + 1) is one contiguous read per node and per slot:
// - nodes[n * (keyCount - 1) + s]: node n's record for segment s (motion::BlurredNodeSegment, 96
//   bytes: its key-s refit with pre-padded child boxes and its references, and the changes to key
//   s + 1 in binary16 rounded outward; count0's motion::kKeysAlikeBit set when the node's child
//   boxes are the same at every key: a ray then takes the key-s boxes as they are, unmoved);
// - triangles[s * keyCount + k]: slot s's triangle at key k (the key-k positions of its vertices,
//   in slot order), so a leaf slot's two keys are 96 contiguous bytes and no index is read; a ray
//   reads both keys of every slot (a still triangle's are the same bits).
// keyCount >= 2 (a blurred frame).
struct BlurredLayout {
  const motion::BlurredNodeSegment* nodes = nullptr;
  const KeyTriangle* triangles = nullptr;
  const Aabb* keyRootBoxes = nullptr;  // per key
  const float* keyTimes = nullptr;     // shutter fractions: first 0, last 1, increasing
  const uint32_t* triIndex = nullptr;  // slot -> triangle id (a hit's triangle)
  uint32_t keyCount = 0;
  int32_t rootRef = makeLeafRef(0);
  uint32_t rootCount = 0;
};

// A blurred frame's parts (a tree set's shutter that crosses switch times, one part per tree, as
// CpuRuntime::updateShutter(parts)): per part its layout, the key arrays a primary hit's surface
// reads, and its first key time (a shutter fraction). A ray at time t takes the last part that
// starts at or before t. One part: `first` alone, and nothing is read to pick it.
struct BlurredPart {
  BlurredLayout layout;
  MotionBvhView view;
  float start = 0.0f;
};
struct BlurredShutter {
  BlurredPart first;
  const BlurredPart* later = nullptr;  // device memory: parts 1, 2, ...
  uint32_t laterCount = 0;
};

// What the layout is built from: keyNodes (keyCount blocks of nodeCount nodes), keyPositions
// (keyCount blocks of keyStride floats, xyz per vertex), slotVertices (3 vertex ids per slot). With
// keyRoots (the batch refit's roots, per key) it also writes the keys' root boxes into keyRootBoxes
// and the instant state of the last key: its nodes into lastNodes, its root box into lastRoot, its
// keyStride floats of positions into lastPositions (the copies of a batch update, in the same launch).
struct BlurredLayoutSources {
  const GpuBvhNode* keyNodes = nullptr;
  uint32_t nodeCount = 0;
  const float* keyPositions = nullptr;
  uint64_t keyStride = 0;
  const uint32_t* slotVertices = nullptr;
  uint32_t slots = 0, keyCount = 0;
  const RootInfo* keyRoots = nullptr;  // null: no root boxes and no instant state
  Aabb* keyRootBoxes = nullptr;
  GpuBvhNode* lastNodes = nullptr;
  RootInfo* lastRoot = nullptr;
  float* lastPositions = nullptr;
};

// Builds the layout (nodes: (keyCount - 1) * nodeCount records, triangles: keyCount * slots) in one launch:
// one thread per node (all its keys) and per slot (all its keys), then the copies.
void launchBuildBlurredLayout(const BlurredLayoutSources& from, motion::BlurredNodeSegment* nodes, KeyTriangle* triangles,
                              cudaStream_t stream);

// Traces rays[i] at shutter fraction times[i], each in its part: closest hits into `hits`, or
// (occluded non-null) any hits into `occluded`.
void launchBlurredTrace(const BlurredShutter& frame, const Ray* rays, const float* times, uint32_t count, Hit* hits,
                        uint8_t* occluded, cudaStream_t stream);

}  // namespace tsah::cuda::detail
