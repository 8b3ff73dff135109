// The two-level runtime's device data built from a source's tree (two_level_device_data.hpp).
#include "two_level_device_data.hpp"

#include <algorithm>

#include "kernels.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda {

detail::RootInfo rootOf(const FlatBvh& tree) {
  detail::RootInfo root;
  root.ref = tree.rootRef;
  root.count = tree.rootCount;
  root.box = tree.rootBoxes.empty() ? Aabb{} : tree.rootBoxes[0];
  return root;
}

DeviceRefitParts::DeviceRefitParts(const RefitParts& host, cudaStream_t stream)
    : parts(toDevice(host.parts, stream)),
      parentSlot(toDevice(host.parentSlot, stream)),
      globalNode(toDevice(host.globalNode, stream)),
      items(toDevice(host.items, stream)),
      subtreeCount(host.subtreeCount()),
      maxNodeCount(host.maxNodeCount()),
      hasTop(host.hasTop) {
  for (const RefitPart& p : host.parts)
    poseSharedBytes = std::max(poseSharedBytes, detail::partRefitBytes(p.nodeCount, p.slotCount));
}

KeyBoxes refitAtKeyframes(const FlatBvh& topology, const anim::Animation& a, std::span<const float> restPositions,
                          const SourceRefitInputs& in, cudaStream_t stream) {
  KeyBoxes out;
  const uint32_t keys = a.keyframeCount();
  const std::size_t nodeCount = topology.nodes.size();
  if (!a.allMoving()) {  // some vertices (or all, when none moves) hold their rest positions
    std::vector<uint32_t> rank(a.vertexCount(), detail::kStaticVertex);
    for (uint32_t r = 0; r < a.movingVertices().size(); ++r) rank[a.movingVertices()[r]] = r;
    out.movingIndex = toDevice(rank, stream);
  }
  // The refit writes every child box of every node and each root's box, all the keyed update reads.
  out.nodes = DeviceBuffer<GpuBvhNode>(nodeCount * keys);
  out.roots = DeviceBuffer<detail::RootInfo>(keys);
  std::vector<detail::FrameParams> frames;
  for (uint32_t k = 0; k < keys; ++k) frames.push_back(detail::blendFrame(k, 0.0f, a.movingVertexCount()));
  const DeviceBuffer<detail::FrameParams> deviceFrames = toDevice(frames, stream);
  // The keyframes refitted as a batch of trees, a few at a time (their positions are temporary).
  constexpr std::size_t kChunkBytes = std::size_t(64) << 20;
  const std::size_t perKey = std::max<std::size_t>(1, restPositions.size_bytes());
  const auto chunk = uint32_t(std::clamp<std::size_t>(kChunkBytes / perKey, 1, keys));
  std::vector<float> rest;
  for (uint32_t i = 0; i < chunk; ++i) rest.insert(rest.end(), restPositions.begin(), restPositions.end());
  DeviceBuffer<float> positions = toDevice(rest, stream);
  DeviceBuffer<uint32_t> counters(std::max<std::size_t>(1, std::size_t(topology.interiorCount) * chunk));
  detail::BatchStrides strides;
  strides.positions = restPositions.size();
  strides.nodes = nodeCount;
  strides.counters = topology.interiorCount;
  for (uint32_t first = 0; first < keys; first += chunk) {
    const uint32_t count = std::min(chunk, keys - first);
    detail::launchBatchInterpolate(in.keyframes, in.movingIds, deviceFrames.data() + first, positions.data(),
                                   in.movingCount, count, strides.positions, stream);
    CUDA_CHECK(cudaMemsetAsync(counters.data(), 0, counters.bytes(), stream));
    detail::launchBatchRefit(out.nodes.data() + first * nodeCount, in.nodeParent, in.leaves, in.leafCount,
                             in.slotVertices, positions.data(), counters.data(), out.roots.data() + first,
                             count, strides, stream);
  }
  // The temporaries are freed when this returns: the refits must be done with them.
  CUDA_CHECK(cudaStreamSynchronize(stream));
  return out;
}

}  // namespace tsah::cuda
