#pragma once
// The per-frame conversion of a rebuilt binary tree (GpuRebuilder) into the compressed 8-wide
// layout on the device: one persistent kernel walks the tree level by level with the per-node
// steps of tsah/cwbvh_convert.hpp (greedy opening by surface area, octant slots, cwbvhQuantize),
// each node done by 8 lanes (a lane per child), numbering each level's nodes and triangles with a
// grid-wide prefix sum, so the result is byte-identical to the host emulation tsah::convertToCwbvh.
#include <cuda_runtime_api.h>

#include <cstdint>

#include "device_types.hpp"
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah_cuda/device_buffer.hpp"

namespace tsah::cuda::detail {

class GpuCwbvhConverter {
 public:
  explicit GpuCwbvhConverter(uint32_t triangles);

  // Puts the conversion of the binary tree on the stream: nodeCount nodes (only those reachable
  // from root->ref are read), slotTri: binary slot -> triangle id, root: on the device. Writes
  // nodes() and triIndex() (new slot -> triangle id). No host synchronization and no pageable
  // copy: capturable into a CUDA graph. mergeLimit <= kCwbvhMaxLeafTriangles.
  void enqueue(const GpuBvhNode* nodes, uint32_t nodeCount, const uint32_t* slotTri, const RootInfo* root,
               uint32_t mergeLimit, cudaStream_t stream);
  // After the stream has run the conversion: its node count. Throws tsah::Failure when the kernel
  // found the binary tree invalid (a reference out of range, leaves of more than 64 triangles
  // under one wide node, triangles in no leaf).
  uint32_t collect(cudaStream_t stream);

  const CwbvhNode* nodes() const { return nodes_.data(); }
  const uint32_t* triIndex() const { return triIndex_.data(); }
  uint32_t nodeCount() const { return nodeCount_; }
  uint32_t levels() const { return levels_; }  // of the last conversion (= CwbvhTree::depth)
  // The last conversion's nodes and triIndex (rootRef 0; nothing else of CwbvhTree is filled).
  CwbvhTree download(cudaStream_t stream) const;

 private:
  uint32_t n_;
  uint32_t nodeCount_ = 0, levels_ = 0;
  int blocks_ = 1;
  DeviceBuffer<CwbvhNode> nodes_;
  DeviceBuffer<int32_t> starts_;   // per wide node: the binary node it starts at
  DeviceBuffer<uint32_t> triIndex_;
  DeviceBuffer<uint2> blockSums_;  // per block, two rounds: (interior children, leaf triangles)
  DeviceBuffer<uint32_t> words_;   // grid barrier, node count, error
};

}  // namespace tsah::cuda::detail
