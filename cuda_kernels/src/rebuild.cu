// The per-frame GPU rebuilds' host side, GpuRebuilder (rebuild.hpp): buffers, the steps of LBVH and
// HLBVH-SAH enqueued in order (rebuild_*.cu), timings, and the downloads of the built tree.
#include <algorithm>
#include <string>

#include "kernels.hpp"
#include "launch.hpp"
#include "rebuild.hpp"
#include "rebuild_steps.cuh"
#include "tsah/layout/traversal.hpp"

namespace tsah::cuda::detail {

GpuRebuilder::GpuRebuilder(uint32_t primitives, Layout layout) : n_(primitives), events_(8) {  // see collect
  if (n_ == 0) throw tsah::DataError("GPU rebuild: no primitives");
  if (n_ > kMaxGpuTriangles) throw tsah::DataError("GPU rebuild: too many primitives");
  const std::size_t n = n_;
  const std::size_t clusterCap = std::min<std::size_t>(n, kMaxClusters);
  const std::size_t nodeCap = std::max<std::size_t>(1, (n - 1) + (clusterCap - 1));
  triBox_.resize(n);
  mortonIn_.resize(n);
  mortonOut_.resize(n);
  idsIn_.resize(n);
  sortedIds_.resize(n);
  slotTri_.resize(n);
  leafParent_.resize(n);
  centroidBounds_.resize(6);
  children_.resize(nodeCap);
  nodeParent_.resize(nodeCap);
  counters_.resize(nodeCap);
  nodeInfo_.resize(3 * nodeCap);
  nodes_.resize(nodeCap);
  root_.resize(1);
  // HLBVH-SAH.
  headFlags_.resize(n);
  clusterOf_.resize(n);
  leafParentRadix_.resize(n);
  slotMap_.resize(n);
  nodeRange_.resize(std::max<std::size_t>(1, n - 1));
  for (auto* b : {&clusterBegin_, &clusterEnd_, &clusterCell_, &clusterParent_, &orderA_, &orderB_, &finalOrder_,
                  &newBegin_, &taskReady_})
    b->resize(clusterCap);
  clusterRoot_.resize(clusterCap);
  clusterBox_.resize(clusterCap);
  tasks_.resize(clusterCap);
  queueWords_.resize(kQueueWords);

  std::size_t sortBytes = 0, scanBytes = 0;
  sortMortonCodes(nullptr, sortBytes, mortonIn_.data(), mortonOut_.data(), idsIn_.data(), sortedIds_.data(), n_,
                  nullptr);
  scanClusterHeads(nullptr, scanBytes, headFlags_.data(), clusterOf_.data(), n_, nullptr);
  cubTemp_.resize(std::max<std::size_t>({sortBytes, scanBytes, 1}));
  topBlocks_ = clusterTreeBlocks();
  int device = 0, sms = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  boxBlocks_ = 8 * sms;
  if (layout == Layout::Cwbvh) wide_ = std::make_unique<GpuCwbvhConverter>(n_);
}

GpuRebuilder::~GpuRebuilder() = default;

void GpuRebuilder::checkOptions(const RebuildOptions& options) const {
  if (options.maxLeafSize == 0) throw tsah::ConfigError("GPU rebuild: maxLeafSize must be at least 1");
  if (wide_ && options.collapse && options.maxLeafSize > kCwbvhMaxLeafTriangles)
    throw tsah::ConfigError("GPU rebuild: the cwbvh layout takes leaves of at most " +
                            std::to_string(kCwbvhMaxLeafTriangles) + " triangles (maxLeafSize is " +
                            std::to_string(options.maxLeafSize) + ")");
}

void GpuRebuilder::enqueue(const uint32_t* indices, const float* positions, const RebuildOptions& options,
                           WoopTriangle* woop, cudaStream_t stream) {
  checkOptions(options);
  built_ = false;
  events_.record(0, stream);
  // The triangles' boxes (kept for the later steps) and the Morton codes over their centroid bounds.
  centroidBounds_.fillBytes(0x7f, stream);
  launchMortonCodes(indices, positions, n_, unsigned(boxBlocks_), triBox_.data(), centroidBounds_.data(),
                    mortonIn_.data(), idsIn_.data(), stream);
  enqueueHierarchy(triBox_.data(), options, stream);
  if (options.woop) launchWoop(wide_ ? wide_->triIndex() : slotTri_.data(), n_, indices, positions, woop, stream);
  events_.record(7, stream);
}

void GpuRebuilder::enqueueBoxes(const Aabb* boxes, const RebuildOptions& options, cudaStream_t stream) {
  checkOptions(options);
  built_ = false;
  events_.record(0, stream);
  centroidBounds_.fillBytes(0x7f, stream);
  launchMortonCodes(boxes, n_, unsigned(boxBlocks_), centroidBounds_.data(), mortonIn_.data(), idsIn_.data(), stream);
  enqueueHierarchy(boxes, options, stream);
  events_.record(7, stream);
}

void GpuRebuilder::enqueueHierarchy(const Aabb* boxes, const RebuildOptions& options, cudaStream_t stream) {
  const bool wide = wide_ != nullptr;
  const bool hlbvh = options.method == RebuildMethod::HlbvhSah;
  const uint32_t n = n_;
  events_.record(1, stream);

  std::size_t tempBytes = cubTemp_.size();
  sortMortonCodes(cubTemp_.data(), tempBytes, mortonIn_.data(), mortonOut_.data(), idsIn_.data(), sortedIds_.data(), n,
                  stream);
  events_.record(2, stream);

  const uint32_t* keys = mortonOut_.data();
  if (hlbvh) {
    launchClusterHeads(keys, n, headFlags_.data(), stream);
    tempBytes = cubTemp_.size();
    scanClusterHeads(cubTemp_.data(), tempBytes, headFlags_.data(), clusterOf_.data(), n, stream);
    taskReady_.fillBytes(0, stream);
    ClusterSetup setup{clusterBegin_.data(), clusterEnd_.data(), clusterCell_.data(), clusterRoot_.data(),
                       clusterParent_.data(), orderA_.data(), finalOrder_.data(), tasks_.data(),
                       taskReady_.data(), queueWords_.data()};
    launchClusterSetup(keys, n, clusterOf_.data(), setup, stream);
  }
  if (n >= 2) {
    KarrasOutput out{children_.data(), nodeParent_.data(), hlbvh ? leafParentRadix_.data() : leafParent_.data(),
                     hlbvh ? nodeRange_.data() : nullptr, clusterOf_.data(), clusterRoot_.data()};
    launchRadixTree(keys, n, out, stream);
  } else {  // one primitive: no interior node; 0xff bytes are kNoParent
    CUDA_CHECK(cudaMemsetAsync(hlbvh ? leafParentRadix_.data() : leafParent_.data(), 0xff, sizeof(uint32_t), stream));
  }
  events_.record(3, stream);

  if (hlbvh) {
    launchClusterBoxes(sortedIds_.data(), boxes, clusterBegin_.data(), clusterEnd_.data(), queueWords_.data(),
                       clusterBox_.data(), n, stream);
    TopParams top{clusterBegin_.data(), clusterEnd_.data(), clusterCell_.data(), clusterBox_.data(),
                  clusterRoot_.data(), orderA_.data(), orderB_.data(), finalOrder_.data(), clusterParent_.data(),
                  children_.data(), nodeParent_.data(), n - 1, tasks_.data(), taskReady_.data(),
                  queueWords_.data()};
    launchClusterTree(top, topBlocks_, stream);
    launchClusterSlots(finalOrder_.data(), clusterBegin_.data(), clusterEnd_.data(), queueWords_.data(),
                       newBegin_.data(), stream);
    launchPermute(n, clusterOf_.data(), clusterBegin_.data(), clusterEnd_.data(), newBegin_.data(),
                  clusterParent_.data(), sortedIds_.data(), leafParentRadix_.data(), slotTri_.data(), slotMap_.data(),
                  leafParent_.data(), stream);
    if (n >= 2)
      launchRemap(n, keys, nodeRange_.data(), clusterOf_.data(), clusterRoot_.data(), clusterParent_.data(),
                  queueWords_.data(), slotMap_.data(), children_.data(), nodeParent_.data(), stream);
  } else {
    CUDA_CHECK(cudaMemcpyAsync(slotTri_.data(), sortedIds_.data(), std::size_t(n) * sizeof(uint32_t),
                               cudaMemcpyDeviceToDevice, stream));
  }
  events_.record(4, stream);

  counters_.fillBytes(0, stream);
  BottomUpParams bu{n,
                    slotTri_.data(),
                    leafParent_.data(),
                    boxes,
                    children_.data(),
                    nodeParent_.data(),
                    counters_.data(),
                    nodeInfo_.data(),
                    nodes_.data(),
                    root_.data(),
                    options.cost.ct,
                    options.cost.ci,
                    options.maxLeafSize};
  launchBottomUp(bu, options.collapse, stream);
  events_.record(5, stream);

  // The wide layout: the binary nodes' array (unreferenced nodes are never read); the triangle
  // build then writes the Woop triangles of the wide layout's slots.
  if (wide)
    wide_->enqueue(nodes_.data(), uint32_t(nodes_.size()), slotTri_.data(), root_.data(), options.wideMergeTriangles,
                   stream);
  events_.record(6, stream);
}

RebuildTimings GpuRebuilder::collect(const RebuildOptions& options) {
  const bool hlbvh = options.method == RebuildMethod::HlbvhSah;
  RebuildTimings timings;
  events_.wait(7);

  timings.mortonMs = events_.ms(0, 1);
  timings.sortMs = events_.ms(1, 2);
  timings.hierarchyMs = events_.ms(2, 3);
  timings.topMs = events_.ms(3, 4);
  timings.bottomUpMs = events_.ms(4, 5);
  timings.wideMs = wide_ ? events_.ms(5, 6) : 0.0;  // without a conversion, two events back to back
  timings.woopMs = events_.ms(6, 7);
  RootInfo root;
  CUDA_CHECK(cudaMemcpy(&root, root_.data(), sizeof root, cudaMemcpyDeviceToHost));
  timings.interiorNodes = root.interiorCount;
  timings.leaves = root.interiorCount + 1;
  timings.depth = root.depth;
  if (hlbvh) {
    uint32_t clusters = 0;
    CUDA_CHECK(cudaMemcpy(&clusters, queueWords_.data() + kClusterCount, sizeof clusters, cudaMemcpyDeviceToHost));
    timings.clusters = clusters;
  }
  if (root.depth > kTraversalStackSize)
    throw tsah::Failure("GPU rebuild: the tree is " + std::to_string(root.depth) +
                        " levels deep, more than the traversal stack of " + std::to_string(kTraversalStackSize));
  // The wide tree is no deeper than the binary one (every wide child starts below its parent's
  // binary node), so the check above bounds the wide traversal's stack too.
  if (wide_) {
    timings.wideNodes = wide_->collect(nullptr);
    timings.wideLevels = wide_->levels();
  }
  built_ = true;
  return timings;
}

RebuildTimings GpuRebuilder::build(const uint32_t* indices, const float* positions, const RebuildOptions& options,
                                   WoopTriangle* woop, cudaStream_t stream) {
  enqueue(indices, positions, options, woop, stream);
  return collect(options);
}

FlatBvh GpuRebuilder::downloadArrays(cudaStream_t stream) const {
  if (!built_) throw tsah::ConfigError("GPU rebuild: no tree has been built");
  const RootInfo root = root_.download(stream)[0];
  FlatBvh raw;
  raw.nodes = nodes_.download(stream);
  raw.interiorCount = uint32_t(raw.nodes.size());
  raw.leafCount = root.interiorCount + 1;
  raw.depth = root.depth;
  raw.rootRef = root.ref;
  raw.rootCount = root.count;
  raw.rootBoxes = {root.box};
  raw.triIndex = slotTri_.download(stream);
  return raw;
}

Bvh GpuRebuilder::download(cudaStream_t stream) const {
  if (!built_) throw tsah::ConfigError("GPU rebuild: no tree has been built");
  const std::vector<GpuBvhNode> nodes = nodes_.download(stream);
  const std::vector<RootInfo> root = root_.download(stream);
  Bvh bvh;
  bvh.frameCount = 1;
  bvh.primIds = slotTri_.download(stream);
  bvh.root = 0;
  auto addNode = [&](uint32_t parent, const Aabb& box) {
    bvh.nodes.emplace_back().parent = parent;
    bvh.boxes.push_back(box);
    return uint32_t(bvh.nodes.size() - 1);
  };
  const uint32_t rootIndex = addNode(kInvalidIndex, root[0].box);
  // (device reference, leaf count, Bvh index) of nodes still to expand.
  struct Item {
    int32_t ref;
    uint32_t count, index;
  };
  std::vector<Item> stack{{root[0].ref, root[0].count, rootIndex}};
  const std::size_t limit = nodes.size() + 1;
  std::size_t interiorSeen = 0;
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    if (isLeafRef(item.ref)) {
      const uint32_t first = leafFirstSlot(item.ref);
      if (item.count == 0 || std::size_t(first) + item.count > n_)
        throw tsah::Failure("GPU rebuild: a leaf's slot range is out of bounds");
      bvh.nodes[item.index].primBegin = first;
      bvh.nodes[item.index].primCount = item.count;
      continue;
    }
    if (uint32_t(item.ref) >= nodes.size() || ++interiorSeen > limit)
      throw tsah::Failure("GPU rebuild: a node reference is out of range or the nodes form a cycle");
    const GpuBvhNode& node = nodes[uint32_t(item.ref)];
    const uint32_t left = addNode(item.index, node.childBox(0));
    const uint32_t right = addNode(item.index, node.childBox(1));
    bvh.nodes[item.index].left = left;
    bvh.nodes[item.index].right = right;
    stack.push_back({node.ref1, node.count1, right});
    stack.push_back({node.ref0, node.count0, left});
  }
  return bvh;
}

}  // namespace tsah::cuda::detail
