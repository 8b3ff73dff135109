#pragma once
// The per-frame GPU rebuild baselines (host side; the steps in rebuild_*.cu, rebuild_steps.cuh).
//
//  LBVH:      triangle boxes and centroid bounds -> 30-bit Morton codes -> CUB radix sort ->
//             Karras (2012) radix tree -> bottom-up boxes with atomic counters, where the leaf
//             collapse is decided and the GpuBvhNode of every interior node is written.
//  HLBVH-SAH: the same Morton codes and radix tree; the runs of equal top-15-bit prefixes are the
//             clusters (their subtrees of the radix tree are the spatial-median bottom levels); a
//             binned SAH tree over the clusters replaces the radix tree above them (Garanzha et al.
//             2011), built by persistent blocks taking nodes from a queue; the triangles are then
//             reordered so that every subtree of the final tree covers a contiguous slot range, and
//             the same bottom-up pass collapses and writes the nodes.
// Both also build over given boxes (a TLAS over instance boxes): the same steps, the boxes read
// where the triangle build computes them (the triangle build is its triangles' boxes, then the box
// build). Nodes are indexed by the radix tree (0 .. n-2) and, for HLBVH-SAH, the cluster tree
// after them; nodes collapsed into leaves or replaced by the cluster tree stay in the array
// unreferenced.
// Layout cwbvh: the binary tree is then converted into the compressed 8-wide layout on the device
// (cwbvh_rebuild.hpp), and the Woop triangles are those of the wide layout's slots.
#include <cuda_runtime_api.h>

#include <cstdint>
#include <memory>

#include "cwbvh_rebuild.hpp"
#include "device_types.hpp"
#include "event_timer.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/rebuild_types.hpp"

namespace tsah::cuda::detail {

class GpuRebuilder {
 public:
  // `primitives`: the triangles, or the boxes, of every build. layout cwbvh: every build is
  // followed by its conversion into the compressed 8-wide layout.
  GpuRebuilder(uint32_t primitives, Layout layout);
  ~GpuRebuilder();
  GpuRebuilder(const GpuRebuilder&) = delete;
  GpuRebuilder& operator=(const GpuRebuilder&) = delete;

  // Builds a tree over the triangles (indices: 3 per triangle) at the given device positions,
  // and with layout cwbvh its compressed 8-wide form. Writes woop (one per slot of the layout)
  // when options.woop. Synchronizes at the end (timings, tree size).
  RebuildTimings build(const uint32_t* indices, const float* positions, const RebuildOptions& options,
                       WoopTriangle* woop, cudaStream_t stream);
  // build() in two halves: enqueue() only puts work on the stream (no host synchronization, no
  // pageable copies, so it can be captured into a CUDA graph); collect() waits for it and reads the
  // timings and the size of the tree.
  void enqueue(const uint32_t* indices, const float* positions, const RebuildOptions& options, WoopTriangle* woop,
               cudaStream_t stream);
  // enqueue() over given device boxes (one per primitive, by id; a leaf slot's triIndex() is a
  // primitive id): leaves of at most options.maxLeafSize primitives, no Woop triangles
  // (options.woop is not read). The boxes must stay as they are until the build has run.
  void enqueueBoxes(const Aabb* boxes, const RebuildOptions& options, cudaStream_t stream);
  RebuildTimings collect(const RebuildOptions& options);

  const GpuBvhNode* nodes() const { return nodes_.data(); }
  const uint32_t* triIndex() const { return slotTri_.data(); }
  const RootInfo* root() const { return root_.data(); }
  bool built() const { return built_; }
  // The compressed layout of the last build (null for layout bvh2).
  const GpuCwbvhConverter* wide() const { return wide_.get(); }

  // The last tree as a tsah::Bvh (one frame of boxes: the child boxes stored in the nodes).
  Bvh download(cudaStream_t stream) const;
  // The last tree's arrays exactly as the device holds them (GpuRuntime::downloadRebuiltArrays).
  FlatBvh downloadArrays(cudaStream_t stream) const;

 private:
  void checkOptions(const RebuildOptions& options) const;
  // Every step after the box pass (events 1 .. 6), over `boxes` (by primitive id).
  void enqueueHierarchy(const Aabb* boxes, const RebuildOptions& options, cudaStream_t stream);

  uint32_t n_;
  bool built_ = false;
  std::unique_ptr<GpuCwbvhConverter> wide_;  // layout cwbvh only
  EventTimer events_;
  // Per primitive (by id) and per slot; triBox_: the triangle build's boxes.
  DeviceBuffer<Aabb> triBox_;
  DeviceBuffer<uint32_t> mortonIn_, mortonOut_, idsIn_, sortedIds_, slotTri_, leafParent_;
  DeviceBuffer<int32_t> centroidBounds_;  // 6 order-preserving ints: min xyz, min -xyz
  // Per interior node (radix tree, then cluster tree).
  DeviceBuffer<int2> children_;
  DeviceBuffer<uint32_t> nodeParent_, counters_;
  DeviceBuffer<uint4> nodeInfo_;  // 3 x uint4 per node, see rebuild_bottom_up.cu
  DeviceBuffer<GpuBvhNode> nodes_;
  DeviceBuffer<RootInfo> root_;
  // HLBVH-SAH.
  DeviceBuffer<uint32_t> headFlags_, clusterOf_, clusterBegin_, clusterEnd_, clusterCell_, clusterParent_,
      orderA_, orderB_, finalOrder_, newBegin_, slotMap_, leafParentRadix_, queueWords_, taskReady_;
  DeviceBuffer<int32_t> clusterRoot_;
  DeviceBuffer<Aabb> clusterBox_;
  DeviceBuffer<uint4> tasks_;
  DeviceBuffer<uint2> nodeRange_;
  // CUB scratch.
  DeviceBuffer<unsigned char> cubTemp_;
  int topBlocks_ = 0;
  int boxBlocks_ = 0;
};

}  // namespace tsah::cuda::detail
