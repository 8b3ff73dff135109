#pragma once
// The two-level runtime's device data built from a source's tree at upload
// (two_level_runtime.cpp): its root, its split for block refits and its boxes refitted at every
// keyframe for the keyed pose update.
#include <cuda_runtime_api.h>

#include <cstdint>
#include <span>
#include <vector>

#include "anim/animation.hpp"
#include "device_types.hpp"
#include "refit_topology.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/refit_parts.hpp"
#include "tsah_cuda/device_buffer.hpp"

namespace tsah::cuda {

template <typename T>
DeviceBuffer<T> toDevice(const std::vector<T>& host, cudaStream_t stream) {
  return DeviceBuffer<T>(std::span<const T>(host), stream);
}

// `count` copies of `one` after each other (a batch's arrays, before their first update).
template <typename T>
std::vector<T> repeated(std::span<const T> one, std::size_t count) {
  std::vector<T> out;
  out.reserve(one.size() * count);
  for (std::size_t i = 0; i < count; ++i) out.insert(out.end(), one.begin(), one.end());
  return out;
}

// The tree's root as the device keeps it (reference, count, box).
detail::RootInfo rootOf(const FlatBvh& tree);

// A tree split for block refits (tsah::splitForBlockRefit), on the device.
struct DeviceRefitParts {
  DeviceBuffer<RefitPart> parts;
  DeviceBuffer<uint32_t> parentSlot, globalNode;
  DeviceBuffer<RefitPartItem> items;
  uint32_t subtreeCount = 0, maxNodeCount = 0;
  uint64_t poseSharedBytes = 0;  // the pose kernel's: the most partRefitBytes(nodes, slots) of a part
  bool hasTop = false;

  DeviceRefitParts() = default;
  DeviceRefitParts(const RefitParts& host, cudaStream_t stream);
  detail::RefitPartsView view() const {
    return {parts.data(), parentSlot.data(), globalNode.data(), items.data(), subtreeCount, hasTop ? 1u : 0u};
  }
};

// A source's tree refitted at every keyframe (the keyed pose update, two_level_kernels.hpp's
// KeyedSource): nodes per keyframe, a root per keyframe, and per vertex its rank among the moving
// ones (kStaticVertex for a static one; empty when every vertex moves).
struct KeyBoxes {
  DeviceBuffer<GpuBvhNode> nodes;
  DeviceBuffer<detail::RootInfo> roots;
  DeviceBuffer<uint32_t> movingIndex;
  uint64_t bytes() const { return nodes.bytes() + roots.bytes() + movingIndex.bytes(); }
  // The nodes' and roots' bytes for `keys` keyframes of `topology` (what Config::keyedPoseBytes bounds).
  static uint64_t bytesFor(const FlatBvh& topology, uint32_t keys) {
    return uint64_t(keys) * (topology.nodes.size() * sizeof(GpuBvhNode) + sizeof(detail::RootInfo));
  }
};

// What the refit of a source's tree reads on the device: its keyframes and moving vertices, the
// refit topology and the slots' vertex ids (all the source's, uploaded).
struct SourceRefitInputs {
  const float* keyframes = nullptr;
  const uint32_t* movingIds = nullptr;  // null when every vertex moves
  uint32_t movingCount = 0;
  const uint32_t* nodeParent = nullptr;
  const detail::LeafRecord* leaves = nullptr;
  uint32_t leafCount = 0;
  const uint32_t* slotVertices = nullptr;
};

// `topology` refitted at every keyframe of `a` by the refit kernels, a batch of keyframes at a
// time (restPositions: every vertex, the static ones at rest). Waits for the device before it
// returns (its temporaries are freed then).
KeyBoxes refitAtKeyframes(const FlatBvh& topology, const anim::Animation& a, std::span<const float> restPositions,
                          const SourceRefitInputs& in, cudaStream_t stream);

}  // namespace tsah::cuda
