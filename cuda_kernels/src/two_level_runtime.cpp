// tsah::cuda::GpuTwoLevelRuntime (gpu_two_level.hpp): uploads, the per-frame graphs, the queries.
#include <cuda_runtime_api.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "cwbvh_kernels.hpp"
#include "event_timer.hpp"
#include "kernels.hpp"
#include "rebuild.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/refit_parts.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "two_level_blur.hpp"
#include "two_level_device_data.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda {

struct GpuTwoLevelRuntime::Impl {
  // A source's shared data: topology, indices, keyframes of its moving vertices.
  struct Source {
    FlatBvh topology;
    uint32_t leafCount = 0;
    DeviceBuffer<uint32_t> indices, triIndex, slotVertices, nodeParent, movingIds;
    DeviceBuffer<detail::LeafRecord> leaves;
    DeviceBuffer<float> keyframes;  // every keyframe of the moving vertices (animated sources)
    uint32_t movingCount = 0;
    // Animated sources: keyed (Config::keyedPoses within its byte bound), its tree refitted at
    // every keyframe; else with Config::blockRefits, its split for the poses' block refit.
    bool keyed = false;
    KeyBoxes keyBoxes;
    DeviceRefitParts parts;
    // Config::layout cwbvh: the tree in the compressed layout (collapsed over the source's
    // keyframes), its slots' triangle and vertex ids, and its refit's launches.
    struct Compressed {
      CwbvhTree host;
      DeviceBuffer<uint32_t> triIndex, slotVertices;
      detail::CwbvhRefitPlan plan;
    };
    std::unique_ptr<Compressed> cwbvh;
    detail::KeyedSource keyedView() const {
      return {keyframes.data(), movingIds.empty() ? nullptr : movingIds.data(),
              keyBoxes.movingIndex.empty() ? nullptr : keyBoxes.movingIndex.data(), movingCount,
              slotVertices.data(), topology.triangleCount(), keyBoxes.nodes.data(), keyBoxes.roots.data(),
              uint32_t(topology.nodes.size())};
    }
  };
  // A static source's BLAS: its boxes, positions and Woop triangles, refitted once.
  struct StaticBlas {
    uint32_t source = 0;
    DeviceBuffer<GpuBvhNode> nodes;
    DeviceBuffer<float> positions;
    DeviceBuffer<WoopTriangle> woop;
    DeviceBuffer<uint32_t> counters;
    DeviceBuffer<detail::RootInfo> root;
    DeviceBuffer<CwbvhNode> cwbvhNodes;  // the compressed layout's (nodes then stays empty)
    DeviceBuffer<Aabb> nodeBoxes;        // its refit's scratch
  };
  // The poses of one animated source, updated together: one launch per step for all of them
  // (detail::BatchStrides); pose i of the group has its arrays at i times the strides.
  struct PoseGroup {
    uint32_t source = 0;
    std::vector<uint32_t> poses;  // the scene's pose ids, in batch order
    uint32_t firstFrame = 0;      // its poses' frames in poseFrames / devicePoseFrames
    detail::BatchStrides strides;
    bool blockRefit = false;  // not keyed: its BLAS's parts fit one block's shared memory (launchPoseBlasParts)
    DeviceBuffer<GpuBvhNode> nodes;
    DeviceBuffer<float> positions;
    DeviceBuffer<WoopTriangle> woop;
    DeviceBuffer<uint32_t> counters;  // the global walk's
    DeviceBuffer<Aabb> partBoxes;     // the block refit's: the subtree parts' root boxes per pose
    DeviceBuffer<uint32_t> tickets;   // the block refit's: finished subtree blocks per pose
    DeviceBuffer<detail::RootInfo> roots;
    // The compressed layout's nodes (nodes then stays empty) and its refit's scratch, per pose.
    DeviceBuffer<CwbvhNode> cwbvhNodes;
    DeviceBuffer<Aabb> nodeBoxes, topLeafBoxes;
  };
  struct Graph {
    cudaGraph_t graph = nullptr;
    cudaGraphExec_t exec = nullptr;
  };

  Impl(const TwoLevelScene& s, Config c);
  ~Impl() { releaseDevice(); }
  void create();  // the constructor's work
  // The group holding a pose and the pose's place in it (tsah::ConfigError naming `who` for a pose
  // out of range).
  std::pair<const PoseGroup*, uint32_t> memberOf(uint32_t pose, const char* who) const;
  void uploadCompressed(Source& d, const Blas& blas, std::span<const uint32_t> indices);
  void releaseDevice() noexcept;
  void enqueueFrame(bool refitPoses);
  Graph capture(bool refitPoses);
  detail::TlasScene tlasScene() const;
  template <bool AnyHit, typename Result>
  std::vector<Result> trace(std::span<const Ray> rays, RayPassStats* stats);

  const TwoLevelScene& scene;
  Config config;
  DeviceInfo device;
  cudaStream_t stream = nullptr;
  detail::EventTimer events;
  std::vector<Source> sources;
  std::vector<StaticBlas> statics;
  std::vector<PoseGroup> groups;
  std::vector<uint32_t> staticView;  // per source: its view, or kInvalidIndex when animated
  uint32_t firstPoseView = 0;        // views: the static BLAS, then one per pose in the scene's order
  DeviceBuffer<detail::BlasView> views;
  // What the host writes each frame, in one pinned block mapped into the device's address space,
  // that the graphs copy to one device block with one kernel (a copy node in a graph costs about
  // 10 us whatever its size): the poses' frames (in the groups' batch order), then the instances'
  // states (the rigid graph copies only these).
  uint8_t* hostUpload = nullptr;
  const uint8_t* mappedUpload = nullptr;  // hostUpload's device pointer
  DeviceBuffer<uint8_t> deviceUpload;
  std::size_t instancesOffset = 0, uploadBytes = 0;
  detail::FrameParams* poseFrames = nullptr;  // in hostUpload
  detail::FrameParams* devicePoseFrames = nullptr;  // in deviceUpload
  std::vector<uint32_t> poseFrameIndex;       // per pose: its entry in poseFrames
  std::vector<double> poseLocalTime;
  detail::InstanceState* hostInstances = nullptr;  // in hostUpload
  detail::InstanceState* instances = nullptr;      // in deviceUpload
  DeviceBuffer<Aabb> instanceBoxes;
  // The T-SAH TLAS trees (TwoLevelScene::tlases), checked against the instances. Config::tlas
  // Refit: each one's nodes and refit data on the device (uploadRefitTlas) and its own graphs (they
  // hold its pointers); a rebuild uses the first one's graphs.
  struct DeviceTlas {
    FlatBvh topology;
    uint32_t leafCount = 0;
    DeviceBuffer<GpuBvhNode> nodes;
    DeviceBuffer<uint32_t> parent, counters, triIndex;
    DeviceRefitParts parts;  // the TLAS as one part, for its block refit
    DeviceBuffer<detail::LeafRecord> leaves;
    DeviceBuffer<detail::RootInfo> root;
    bool blockRefit = false;
    Graph fullGraph, rigidGraph;  // with and without the poses' BLAS refits
  };
  std::vector<DeviceTlas> tlases;
  uint32_t tlasPart = 0;  // the TLAS of the last update's time (TwoLevelScene::tlasAt)
  void uploadRefitTlas(DeviceTlas& t);
  uint64_t blockRefitLimit = 0;  // shared bytes a block refit may use (prepareBlockRefits)
  bool tlasBlockRefit = false;
  // Config::tlas a rebuild: the per-frame TLAS over instanceBoxes (its triIndex: slot -> instance).
  std::unique_ptr<detail::GpuRebuilder> tlasRebuilder;
  RebuildOptions tlasRebuild;
  double time = 0.0;
  uint64_t refits = 0;
  detail::TwoLevelQuery query;
};

GpuTwoLevelRuntime::Impl::Impl(const TwoLevelScene& s, Config c) : scene(s), config(c) {
  // The destructor never runs for a throwing constructor (a tree too deep, bad indices, a TLAS
  // missing an instance): the stream and the pinned block are released here.
  try {
    create();
  } catch (...) {
    releaseDevice();
    throw;
  }
}

void GpuTwoLevelRuntime::Impl::create() {
  config.layout = gpuLayout(config.layout);
  if (config.layout != Layout::Bvh2 && config.layout != Layout::Cwbvh)
    throw ConfigError(std::string("GPU two-level runtime: ") + name(config.layout) +
                      " is no GPU layout (bvh2 or cwbvh)");
  const bool compressed = config.layout == Layout::Cwbvh;
  device = describeDevice(config.device);
  CUDA_CHECK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
  events.create(4);
  blockRefitLimit = config.blockRefits ? detail::prepareBlockRefits() : 0;
  const anim::SceneSources& src = scene.scene;
  for (const Blas& blas : scene.blases) {
    const anim::Animation& a = *src.sources[blas.source];
    if (a.keyframeCount() == 0) throw DataError("GPU two-level runtime: a source has no keyframes");
    Source& d = sources.emplace_back();
    d.topology = runtimeTopology(blas.flat, a.triangleCount(), kTraversalStackSize, "GPU two-level runtime: BLAS");
    const detail::RefitTopology r = detail::refitTopology(d.topology);
    d.leafCount = uint32_t(r.leaves.size());
    d.indices = DeviceBuffer<uint32_t>(a.indices(), stream);
    d.triIndex = toDevice(d.topology.triIndex, stream);
    d.slotVertices = toDevice(slotVertexIndices(d.topology.triIndex, a.indices(), "GPU two-level runtime"), stream);
    d.nodeParent = toDevice(r.parent, stream);
    d.leaves = toDevice(r.leaves, stream);
    if (compressed) uploadCompressed(d, blas, a.indices());
    if (blas.animated) {
      d.keyframes = DeviceBuffer<float>(a.motion(), stream);
      d.movingIds = DeviceBuffer<uint32_t>(a.movingVertices(), stream);
      d.movingCount = a.movingVertexCount();
      d.keyed = !compressed && config.keyedPoses &&
                KeyBoxes::bytesFor(d.topology, a.keyframeCount()) <= config.keyedPoseBytes;
      if (!compressed && !d.keyed && config.blockRefits)
        d.parts = DeviceRefitParts(splitForBlockRefit(d.topology, config.refitPartLeaves), stream);
    }
  }
  // A BLAS starts from its source's positions at its start time (the rest positions of the static
  // vertices stay; a pose's interpolation rewrites the moving ones).
  std::vector<detail::BlasView> hostViews;
  staticView.assign(scene.blases.size(), kInvalidIndex);
  for (uint32_t b = 0; b < scene.blases.size(); ++b) {
    if (scene.blases[b].animated) continue;
    const Source& d = sources[b];
    StaticBlas& t = statics.emplace_back();
    t.source = b;
    t.positions = toDevice(src.sources[b]->positionsAt(src.sources[b]->startTime()), stream);
    t.woop.resize(d.topology.triangleCount());
    const detail::RootInfo root = d.cwbvh ? detail::cwbvhRoot(d.cwbvh->host) : rootOf(d.topology);
    t.root = DeviceBuffer<detail::RootInfo>(std::span<const detail::RootInfo>(&root, 1), stream);
    staticView[b] = uint32_t(hostViews.size());
    // Refitted once: static BLAS never change.
    if (Source::Compressed* c = d.cwbvh.get()) {
      t.cwbvhNodes = toDevice(c->host.nodes, stream);
      t.nodeBoxes.resize(c->host.nodes.size());
      detail::launchCwbvhRefit(c->plan, t.cwbvhNodes.data(), t.nodeBoxes.data(), c->slotVertices.data(),
                               t.positions.data(), t.root.data(), stream);
      detail::launchSlotWoop(c->slotVertices.data(), d.topology.triangleCount(), t.positions.data(), t.woop.data(),
                             stream);
      hostViews.push_back({nullptr, t.woop.data(), c->triIndex.data(), d.indices.data(), t.positions.data(),
                           t.root.data(), t.cwbvhNodes.data()});
    } else {
      t.nodes = toDevice(d.topology.nodes, stream);
      t.counters.resize(d.topology.interiorCount);
      if (t.counters.size()) CUDA_CHECK(cudaMemsetAsync(t.counters.data(), 0, t.counters.bytes(), stream));
      detail::launchRefit(t.nodes.data(), d.nodeParent.data(), d.leaves.data(), d.leafCount, d.slotVertices.data(),
                          t.positions.data(), t.counters.data(), t.root.data(), stream);
      detail::launchSlotWoop(d.slotVertices.data(), d.topology.triangleCount(), t.positions.data(), t.woop.data(),
                             stream);
      hostViews.push_back({t.nodes.data(), t.woop.data(), d.triIndex.data(), d.indices.data(), t.positions.data(),
                           t.root.data()});
    }
    ++refits;
  }
  // The poses, grouped by source; each group's arrays hold its poses one after another.
  std::vector<uint32_t> groupOfSource(scene.blases.size(), kInvalidIndex);
  for (uint32_t p = 0; p < scene.poses.size(); ++p) {
    const uint32_t source = scene.poses[p].blas;
    if (groupOfSource[source] == kInvalidIndex) {
      groupOfSource[source] = uint32_t(groups.size());
      groups.emplace_back().source = source;
    }
    groups[groupOfSource[source]].poses.push_back(p);
  }
  firstPoseView = uint32_t(hostViews.size());
  hostViews.resize(hostViews.size() + scene.poses.size());
  poseFrameIndex.assign(scene.poses.size(), 0);
  uint32_t frameCount = 0;
  for (PoseGroup& g : groups) {
    const anim::Animation& a = *src.sources[g.source];
    Source& d = sources[g.source];
    const auto members = uint32_t(g.poses.size());
    const std::vector<float> start = a.positionsAt(a.startTime());
    if (d.keyed)
      d.keyBoxes = refitAtKeyframes(d.topology, a, start,
                                    {d.keyframes.data(), d.movingIds.empty() ? nullptr : d.movingIds.data(),
                                     d.movingCount, d.nodeParent.data(), d.leaves.data(), d.leafCount,
                                     d.slotVertices.data()},
                                    stream);
    const Source::Compressed* c = d.cwbvh.get();
    g.strides.positions = start.size();
    g.strides.nodes = c ? c->host.nodes.size() : d.topology.nodes.size();
    g.strides.woop = d.topology.triangleCount();
    g.strides.counters = d.topology.interiorCount;
    // Blocks per pose: one per subtree part (a grid's y dimension).
    g.blockRefit = !c && !d.keyed && config.blockRefits && d.parts.poseSharedBytes <= blockRefitLimit &&
                   d.parts.subtreeCount <= 65535;
    g.firstFrame = frameCount;
    g.positions = toDevice(repeated(std::span<const float>(start), members), stream);
    if (c) {
      g.cwbvhNodes = toDevice(repeated(std::span<const CwbvhNode>(c->host.nodes), members), stream);
      g.nodeBoxes.resize(c->host.nodes.size() * members);
      g.topLeafBoxes.resize(c->plan.topLeafBoxCount() * members);
    } else {
      g.nodes = toDevice(repeated(std::span<const GpuBvhNode>(d.topology.nodes), members), stream);
    }
    g.woop.resize(g.strides.woop * members);
    if (g.blockRefit) {
      g.partBoxes.resize(std::size_t(d.parts.subtreeCount) * members);
      g.tickets = toDevice(std::vector<uint32_t>(members, 0u), stream);
    } else if (!d.keyed && !c) {
      g.counters.resize(g.strides.counters * members);
    }
    const detail::RootInfo root = c ? detail::cwbvhRoot(c->host) : rootOf(d.topology);
    g.roots = toDevice(std::vector<detail::RootInfo>(members, root), stream);
    for (uint32_t i = 0; i < members; ++i) {
      const uint32_t p = g.poses[i];
      poseFrameIndex[p] = frameCount++;
      detail::BlasView& view = hostViews[firstPoseView + p];
      view = {nullptr, g.woop.data() + i * g.strides.woop, d.triIndex.data(), d.indices.data(),
              g.positions.data() + i * g.strides.positions, g.roots.data() + i};
      if (c) {
        view.cwbvhNodes = g.cwbvhNodes.data() + i * g.strides.nodes;
        view.triIndex = c->triIndex.data();
      } else {
        view.nodes = g.nodes.data() + i * g.strides.nodes;
      }
    }
  }
  views = toDevice(hostViews, stream);
  const uint32_t count = scene.instanceCount();
  static_assert(alignof(detail::InstanceState) <= alignof(detail::FrameParams));
  instancesOffset = std::size_t(frameCount) * sizeof(detail::FrameParams);
  uploadBytes = instancesOffset + std::size_t(count) * sizeof(detail::InstanceState);
  CUDA_CHECK(cudaHostAlloc(reinterpret_cast<void**>(&hostUpload), std::max<std::size_t>(1, uploadBytes),
                           cudaHostAllocMapped));
  void* mapped = nullptr;
  CUDA_CHECK(cudaHostGetDevicePointer(&mapped, hostUpload, 0));
  mappedUpload = static_cast<const uint8_t*>(mapped);
  deviceUpload.resize(std::max<std::size_t>(1, uploadBytes));
  poseFrames = reinterpret_cast<detail::FrameParams*>(hostUpload);
  std::fill_n(poseFrames, frameCount, detail::FrameParams{});
  devicePoseFrames = reinterpret_cast<detail::FrameParams*>(deviceUpload.data());
  hostInstances = reinterpret_cast<detail::InstanceState*>(hostUpload + instancesOffset);
  instances = reinterpret_cast<detail::InstanceState*>(deviceUpload.data() + instancesOffset);
  poseLocalTime.assign(scene.poses.size(), std::numeric_limits<double>::quiet_NaN());
  instanceBoxes.resize(count);
  // The T-SAH TLAS trees are checked whatever the update; only their refit reads them on the device.
  tlases.resize(scene.tlases.size());
  for (std::size_t t = 0; t < tlases.size(); ++t)
    tlases[t].topology = runtimeTopology(flattenBvh(scene.tlases[t].bvh), count, kTraversalStackSize,
                                         "GPU two-level runtime: TLAS " + std::to_string(t));
  if (config.tlas == TlasUpdate::Refit) {
    for (DeviceTlas& t : tlases) uploadRefitTlas(t);
  } else {
    tlasRebuild.method = config.tlas == TlasUpdate::Lbvh ? RebuildMethod::Lbvh : RebuildMethod::HlbvhSah;
    tlasRebuild.maxLeafSize = scene.objective.maxLeafSize;
    tlasRebuild.cost = scene.objective.cost;
    tlasRebuild.woop = false;
    tlasRebuilder = std::make_unique<detail::GpuRebuilder>(count, Layout::Bvh2);
  }
  CUDA_CHECK(cudaStreamSynchronize(stream));
}

void GpuTwoLevelRuntime::Impl::uploadRefitTlas(DeviceTlas& t) {
  const detail::RefitTopology r = detail::refitTopology(t.topology);
  t.leafCount = uint32_t(r.leaves.size());
  t.nodes = toDevice(t.topology.nodes, stream);
  t.parent = toDevice(r.parent, stream);
  t.blockRefit = config.blockRefits && detail::partRefitBytes(t.topology.interiorCount) <= blockRefitLimit;
  if (t.blockRefit)
    t.parts = DeviceRefitParts(splitForBlockRefit(t.topology, std::numeric_limits<uint32_t>::max()), stream);
  else
    t.counters.resize(t.topology.interiorCount);
  t.triIndex = toDevice(t.topology.triIndex, stream);
  t.leaves = toDevice(r.leaves, stream);
  const detail::RootInfo root = rootOf(t.topology);
  t.root = DeviceBuffer<detail::RootInfo>(std::span<const detail::RootInfo>(&root, 1), stream);
}

void GpuTwoLevelRuntime::Impl::uploadCompressed(Source& d, const Blas& blas, std::span<const uint32_t> indices) {
  // The collapse weighs the frames the BLAS was built over, with its build's objective.
  Objective objective = scene.objective;
  objective.k = blas.animated ? objective.k : 0;
  auto c = std::make_unique<Source::Compressed>();
  c->host = buildCwbvh(blas.flat, objective);
  c->triIndex = toDevice(c->host.triIndex, stream);
  c->slotVertices = toDevice(slotVertexIndices(c->host.triIndex, indices, "GPU two-level runtime"), stream);
  c->plan = detail::makeCwbvhRefitPlan(c->host, stream);
  d.cwbvh = std::move(c);
}

void GpuTwoLevelRuntime::Impl::releaseDevice() noexcept {
  for (DeviceTlas& t : tlases)
    for (Graph* g : {&t.fullGraph, &t.rigidGraph}) {
      if (g->exec) cudaGraphExecDestroy(std::exchange(g->exec, nullptr));
      if (g->graph) cudaGraphDestroy(std::exchange(g->graph, nullptr));
    }
  if (stream) cudaStreamSynchronize(stream);
  if (hostUpload) cudaFreeHost(std::exchange(hostUpload, nullptr));
  if (stream) cudaStreamDestroy(std::exchange(stream, nullptr));
}

void GpuTwoLevelRuntime::Impl::enqueueFrame(bool refitPoses) {
  const uint32_t count = scene.instanceCount();
  events.record(0, stream);
  const std::size_t first = refitPoses ? 0 : instancesOffset;
  if (uploadBytes > first)
    detail::launchCopyFromHost(deviceUpload.data() + first, mappedUpload + first, uploadBytes - first, stream);
  if (config.phaseTimings) events.record(1, stream);
  if (refitPoses)  // the poses whose frame is held (FrameParams::held) are skipped by every launch
    for (PoseGroup& g : groups) {
      const Source& d = sources[g.source];
      const auto members = uint32_t(g.poses.size());
      const detail::FrameParams* frames = devicePoseFrames + g.firstFrame;
      if (d.keyed) {
        detail::launchKeyedPoses(d.keyedView(), frames, g.positions.data(), g.nodes.data(), g.woop.data(),
                                 g.roots.data(), members, g.strides, stream);
        continue;
      }
      detail::launchBatchInterpolate(d.keyframes.data(), d.movingIds.size() ? d.movingIds.data() : nullptr, frames,
                                     g.positions.data(), d.movingCount, members, g.strides.positions, stream);
      if (const Source::Compressed* c = d.cwbvh.get()) {
        detail::launchBatchCwbvhRefit(c->plan, g.cwbvhNodes.data(), g.nodeBoxes.data(), g.topLeafBoxes.data(),
                                      c->slotVertices.data(), g.positions.data(), g.roots.data(), members, g.strides,
                                      frames, stream);
        detail::launchBatchSlotWoop(c->slotVertices.data(), d.topology.triangleCount(), g.positions.data(),
                                    g.woop.data(), members, g.strides, stream, frames);
        continue;
      }
      if (g.blockRefit) {
        detail::launchPoseBlasParts(g.nodes.data(), d.parts.view(), d.parts.poseSharedBytes, d.slotVertices.data(),
                                    g.positions.data(), g.woop.data(), g.roots.data(), g.partBoxes.data(),
                                    g.tickets.data(), members, g.strides, frames, stream);
        continue;
      }
      if (g.counters.size()) CUDA_CHECK(cudaMemsetAsync(g.counters.data(), 0, g.counters.bytes(), stream));
      detail::launchBatchRefit(g.nodes.data(), d.nodeParent.data(), d.leaves.data(), d.leafCount,
                               d.slotVertices.data(), g.positions.data(), g.counters.data(), g.roots.data(), members,
                               g.strides, stream, frames);
      detail::launchBatchSlotWoop(d.slotVertices.data(), d.topology.triangleCount(), g.positions.data(),
                                  g.woop.data(), members, g.strides, stream, frames);
    }
  if (config.phaseTimings) events.record(2, stream);
  if (tlasRebuilder) {
    detail::launchInstanceBoxes(instances, views.data(), count, instanceBoxes.data(), stream);
    tlasRebuilder->enqueueBoxes(instanceBoxes.data(), tlasRebuild, stream);
  } else if (DeviceTlas& t = tlases[tlasPart]; t.blockRefit) {
    detail::launchTlasBlock(instances, views.data(), count, instanceBoxes.data(), t.nodes.data(), t.parts.view(),
                            t.parts.maxNodeCount, t.triIndex.data(), t.root.data(), stream);
  } else {
    detail::launchInstanceBoxes(instances, views.data(), count, instanceBoxes.data(), stream);
    if (t.counters.size())
      CUDA_CHECK(cudaMemsetAsync(t.counters.data(), 0, t.counters.size() * sizeof(uint32_t), stream));
    detail::launchTlasRefit(t.nodes.data(), t.parent.data(), t.leaves.data(), t.leafCount, t.triIndex.data(),
                            instanceBoxes.data(), t.counters.data(), t.root.data(), stream);
  }
  events.record(3, stream);
}

GpuTwoLevelRuntime::Impl::Graph GpuTwoLevelRuntime::Impl::capture(bool refitPoses) {
  Graph g;
  CUDA_CHECK(cudaStreamBeginCapture(stream, cudaStreamCaptureModeThreadLocal));
  try {
    enqueueFrame(refitPoses);
  } catch (...) {
    cudaGraph_t broken = nullptr;
    cudaStreamEndCapture(stream, &broken);
    if (broken) cudaGraphDestroy(broken);
    throw;
  }
  CUDA_CHECK(cudaStreamEndCapture(stream, &g.graph));
  CUDA_CHECK(cudaGraphInstantiate(&g.exec, g.graph, 0));
  return g;
}

detail::TlasScene GpuTwoLevelRuntime::Impl::tlasScene() const {
  const bool compressed = config.layout == Layout::Cwbvh;
  if (tlasRebuilder)
    return {tlasRebuilder->nodes(), tlasRebuilder->triIndex(), tlasRebuilder->root(), instances, views.data(),
            instanceBoxes.data(), compressed};
  const DeviceTlas& t = tlases[tlasPart];
  return {t.nodes.data(), t.triIndex.data(), t.root.data(), instances, views.data(), instanceBoxes.data(), compressed};
}

const char* tlasUpdateName(TlasUpdate update) {
  switch (update) {
    case TlasUpdate::Refit: return "refit";
    case TlasUpdate::Lbvh: return "lbvh";
    case TlasUpdate::HlbvhSah: return "hlbvh-sah";
  }
  return "?";
}

TlasUpdate parseTlasUpdate(std::string_view name) {
  for (TlasUpdate u : {TlasUpdate::Refit, TlasUpdate::Lbvh, TlasUpdate::HlbvhSah})
    if (name == tlasUpdateName(u)) return u;
  throw ConfigError("unknown TLAS update '" + std::string(name) + "' (refit, lbvh or hlbvh-sah)");
}

GpuTwoLevelRuntime::GpuTwoLevelRuntime(const TwoLevelScene& scene, Config config)
    : impl_(std::make_unique<Impl>(scene, config)) {
  updateAt(scene.frameTimes.empty() ? scene.scene.start : scene.frameTimes.front());
}

GpuTwoLevelRuntime::~GpuTwoLevelRuntime() = default;

TwoLevelUpdateTimings GpuTwoLevelRuntime::updateAt(double sceneTime) {
  Impl& m = *impl_;
  if (blur_) blur_->end();
  const TwoLevelScene& scene = m.scene;
  const anim::SceneSources& src = scene.scene;
  m.time = sceneTime;
  // Each pose's local time (the time of any of its instances) and keyframe blend.
  std::vector<double> local(scene.poses.size(), std::numeric_limits<double>::quiet_NaN());
  for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
    const uint32_t p = scene.instancePose[i];
    if (p != kInvalidIndex) local[p] = src.instances[i].localTime(sceneTime, *src.sources[scene.poses[p].blas]);
  }
  // A pose whose local time is the last update's is held: the graph's pose launches skip it.
  uint32_t movedPoses = 0;
  for (uint32_t p = 0; p < scene.poses.size(); ++p) {
    const bool held = local[p] == m.poseLocalTime[p];
    movedPoses += held ? 0u : 1u;
    const anim::Animation& a = *src.sources[scene.poses[p].blas];
    const auto [k, alpha] = anim::keyframeBlend(a.times(), local[p]);
    detail::FrameParams& frame = m.poseFrames[m.poseFrameIndex[p]];
    frame = detail::blendFrame(k, alpha, a.movingVertexCount());
    frame.held = held ? 1u : 0u;
  }
  const bool posesMove = movedPoses > 0;
  // The instances' transforms (tsah::TwoLevelRuntime::update's): world(t), its inverse, the view.
  for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
    const anim::Matrix4 world = src.instances[i].worldAt(sceneTime);
    detail::InstanceState& s = m.hostInstances[i];
    const uint32_t p = scene.instancePose[i];
    s.view = p == kInvalidIndex ? m.staticView[src.instances[i].source] : m.firstPoseView + p;
    const std::optional<Affine3x4> space = instanceSpace(world);
    s.visible = space ? 1u : 0u;
    s.toInstance = space.value_or(Affine3x4{});
    std::copy_n(world.begin(), 12, s.world);
  }
  m.tlasPart = m.tlasRebuilder ? 0 : scene.tlasAt(sceneTime);  // a rebuild's graphs: the first TLAS's
  Impl::DeviceTlas& tlas = m.tlases[m.tlasPart];
  Impl::Graph& g = posesMove ? tlas.fullGraph : tlas.rigidGraph;
  if (!g.exec) g = m.capture(posesMove);
  CUDA_CHECK(cudaGraphLaunch(g.exec, m.stream));
  m.events.wait(3);
  TwoLevelUpdateTimings t;
  if (m.config.phaseTimings) {
    t.uploadMs = m.events.ms(0, 1);
    t.blasMs = m.events.ms(1, 2);
    t.tlasMs = m.events.ms(2, 3);
  } else {
    t.blasMs = m.events.ms(0, 3);
  }
  t.blasRefits = movedPoses;
  t.instances = scene.instanceCount();
  t.tlasNodes = tlas.topology.interiorCount;
  if (m.tlasRebuilder) {  // its own events, in the same graph; throws for a tree deeper than the stack
    const RebuildTimings rebuilt = m.tlasRebuilder->collect(m.tlasRebuild);
    t.tlasRebuildMs = rebuilt.buildMs();
    t.tlasNodes = rebuilt.interiorNodes;
  }
  m.refits += t.blasRefits;
  m.poseLocalTime = local;
  return t;
}

template <bool AnyHit, typename Result>
std::vector<Result> GpuTwoLevelRuntime::Impl::trace(std::span<const Ray> in, RayPassStats* stats) {
  return query.run<AnyHit, Result>(in, events, stream, stats,
                                   [&](const Ray* rays, uint32_t count, detail::InstanceHit* hits, uint8_t* occluded) {
                                     detail::launchTwoLevelTrace(tlasScene(), rays, count, hits, occluded, stream);
                                   });
}

std::vector<TwoLevelHit> GpuTwoLevelRuntime::closestHits(std::span<const Ray> rays, RayPassStats* stats) {
  return impl_->trace<false, TwoLevelHit>(rays, stats);
}

std::vector<uint8_t> GpuTwoLevelRuntime::anyHits(std::span<const Ray> rays, RayPassStats* stats) {
  return impl_->trace<true, uint8_t>(rays, stats);
}

std::vector<Aabb> GpuTwoLevelRuntime::downloadInstanceBoxes() const {
  std::vector<Aabb> boxes(impl_->instanceBoxes.size());
  if (!boxes.empty())
    CUDA_CHECK(cudaMemcpy(boxes.data(), impl_->instanceBoxes.data(), boxes.size() * sizeof(Aabb), cudaMemcpyDeviceToHost));
  return boxes;
}

FlatBvh GpuTwoLevelRuntime::downloadTlas() const {
  if (impl_->tlasRebuilder) return flattenBvh(impl_->tlasRebuilder->download(impl_->stream));
  const Impl::DeviceTlas& t = impl_->tlases[impl_->tlasPart];
  FlatBvh tree = t.topology;
  if (!tree.nodes.empty())
    CUDA_CHECK(cudaMemcpy(tree.nodes.data(), t.nodes.data(), tree.nodes.size() * sizeof(GpuBvhNode),
                          cudaMemcpyDeviceToHost));
  detail::RootInfo root;
  CUDA_CHECK(cudaMemcpy(&root, t.root.data(), sizeof(root), cudaMemcpyDeviceToHost));
  tree.rootBoxes.assign(1, root.box);
  return tree;
}

std::pair<const GpuTwoLevelRuntime::Impl::PoseGroup*, uint32_t> GpuTwoLevelRuntime::Impl::memberOf(
    uint32_t pose, const char* who) const {
  if (pose >= scene.poses.size())
    throw ConfigError(std::string(who) + ": pose " + std::to_string(pose) + " of " + std::to_string(scene.poses.size()));
  const uint32_t frame = poseFrameIndex[pose];
  const auto group = std::find_if(groups.begin(), groups.end(), [&](const PoseGroup& g) {
    return frame >= g.firstFrame && frame < g.firstFrame + g.poses.size();
  });
  return {&*group, frame - group->firstFrame};
}

FlatBvh GpuTwoLevelRuntime::downloadPoseTree(uint32_t pose) const {
  const Impl& m = *impl_;
  if (m.config.layout != Layout::Bvh2)
    throw ConfigError("downloadPoseTree: the BLAS are in the compressed layout (downloadPoseCwbvh)");
  const auto [group, member] = m.memberOf(pose, "downloadPoseTree");
  FlatBvh tree = m.sources[group->source].topology;
  if (!tree.nodes.empty())
    CUDA_CHECK(cudaMemcpy(tree.nodes.data(), group->nodes.data() + member * group->strides.nodes,
                          tree.nodes.size() * sizeof(GpuBvhNode), cudaMemcpyDeviceToHost));
  detail::RootInfo root;
  CUDA_CHECK(cudaMemcpy(&root, group->roots.data() + member, sizeof(root), cudaMemcpyDeviceToHost));
  tree.rootBoxes.assign(1, root.box);
  return tree;
}

CwbvhTree GpuTwoLevelRuntime::downloadPoseCwbvh(uint32_t pose) const {
  const Impl& m = *impl_;
  if (m.config.layout != Layout::Cwbvh)
    throw ConfigError("downloadPoseCwbvh: the BLAS are in the binary layout (downloadPoseTree)");
  const auto [group, member] = m.memberOf(pose, "downloadPoseCwbvh");
  CwbvhTree tree = m.sources[group->source].cwbvh->host;
  if (!tree.nodes.empty())
    CUDA_CHECK(cudaMemcpy(tree.nodes.data(), group->cwbvhNodes.data() + member * group->strides.nodes,
                          tree.nodes.size() * sizeof(CwbvhNode), cudaMemcpyDeviceToHost));
  detail::RootInfo root;
  CUDA_CHECK(cudaMemcpy(&root, group->roots.data() + member, sizeof(root), cudaMemcpyDeviceToHost));
  tree.rootBox = root.box;
  return tree;
}

double GpuTwoLevelRuntime::time() const { return impl_->time; }
uint64_t GpuTwoLevelRuntime::blasRefits() const { return impl_->refits; }
uint64_t GpuTwoLevelRuntime::keyBoxBytes() const {
  uint64_t bytes = 0;
  for (const Impl::Source& d : impl_->sources) bytes += d.keyBoxes.bytes();
  return bytes;
}
const DeviceInfo& GpuTwoLevelRuntime::device() const { return impl_->device; }
const TwoLevelScene& GpuTwoLevelRuntime::scene() const { return impl_->scene; }
detail::TwoLevelTraceAccess GpuTwoLevelRuntime::traceAccess() const {
  return {impl_->tlasScene(), blurred() ? &blur_->scene() : nullptr, impl_->stream};
}

detail::TwoLevelBlurAccess GpuTwoLevelRuntime::blurAccess() {
  Impl& m = *impl_;
  // A blurred frame refits the T-SAH TLAS of the close's part (the last update's time) at every
  // key; with a rebuilt TLAS its refit data is uploaded at the first shutter that needs it.
  Impl::DeviceTlas& t = m.tlases[m.scene.tlasAt(m.time)];
  if (t.leaves.empty()) m.uploadRefitTlas(t);
  detail::TwoLevelBlurAccess a;
  a.scene = &m.scene;
  a.stream = m.stream;
  for (const Impl::Source& d : m.sources)
    a.sources.push_back({&d.topology, d.keyframes.data(), d.movingIds.empty() ? nullptr : d.movingIds.data(),
                         d.movingCount, d.nodeParent.data(), d.leaves.data(), d.leafCount, d.slotVertices.data(),
                         d.triIndex.data()});
  a.tlas = &t.topology;
  a.tlasParent = t.parent.data();
  a.tlasLeaves = t.leaves.data();
  a.tlasLeafCount = t.leafCount;
  a.tlasTriIndex = t.triIndex.data();
  a.instances = m.instances;
  a.views = m.views.data();
  a.compressedBlas = m.config.layout == Layout::Cwbvh;
  return a;
}

}  // namespace tsah::cuda
