#include "tsah_cuda/gpu_runtime.hpp"

#include <algorithm>
#include <functional>
#include <new>
#include <string>

#include "anim/animation.hpp"
#include "tsah/base/error.hpp"
#include "cwbvh_kernels.hpp"
#include "kernels.hpp"
#include "refit_topology.hpp"
#include "runtime_impl.hpp"
#include "tsah/layout/moving_parts.hpp"

#include <utility>
#include "tsah/layout/traversal.hpp"

namespace tsah::cuda {

const char* rebuildMethodName(RebuildMethod method) {
  return method == RebuildMethod::Lbvh ? "lbvh" : "hlbvh-sah";
}

RebuildMethod parseRebuildMethod(std::string_view name) {
  if (name == "lbvh") return RebuildMethod::Lbvh;
  if (name == "hlbvh-sah" || name == "hlbvh") return RebuildMethod::HlbvhSah;
  throw tsah::ConfigError("unknown GPU rebuild method '" + std::string(name) + "' (expected lbvh or hlbvh-sah)");
}

GpuRuntime::Impl::Impl(const TreeSet& set, const anim::Animation& animation, Config cfg) : config(cfg) {
  config.layout = gpuLayout(config.layout);
  if (config.layout != Layout::Bvh2 && config.layout != Layout::Cwbvh)
    throw tsah::ConfigError(std::string("GPU runtime: ") + name(config.layout) + " is no GPU layout (bvh2 or cwbvh)");
  triangles = animation.triangleCount();
  vertices = animation.vertexCount();
  if (triangles == 0) throw tsah::DataError("GPU runtime: the animation has no triangles");
  if (animation.keyframeCount() == 0) throw tsah::DataError("GPU runtime: the animation has no keyframes");
  if (set.trees.empty() || set.ranges.size() != set.trees.size())
    throw tsah::DataError("GPU runtime: the tree set holds no trees (or not one time range per tree)");
  if (!set.builds.empty() && set.builds.size() != set.trees.size())
    throw tsah::DataError("GPU runtime: the tree set holds build infos, but not one per tree");
  const auto idx = animation.indices();
  for (uint32_t v : idx)
    if (v >= vertices) throw tsah::DataError("GPU runtime: a triangle refers to a vertex out of range");
  // Every tree is checked (and its runtime topology made) before the device is touched, so a bad
  // tree leaves no stream or pinned memory behind (the destructor never runs for a throwing ctor).
  std::vector<FlatBvh> topologies;
  topologies.reserve(set.trees.size());
  for (const FlatBvh& t : set.trees) topologies.push_back(runtimeTopology(t, triangles, kTraversalStackSize, "GPU runtime"));

  try {
    createOnDevice(set, animation, std::move(topologies));
  } catch (...) {
    releaseDevice();
    throw;
  }
}

void GpuRuntime::Impl::createOnDevice(const TreeSet& set, const anim::Animation& animation,
                                      std::vector<FlatBvh> topologies) {
  CUDA_CHECK(cudaSetDevice(config.device));
  device = describeDevice(config.device);
  CUDA_CHECK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
  CUDA_CHECK(cudaStreamCreateWithFlags(&sideStream, cudaStreamNonBlocking));
  events.create(16);
  times.assign(animation.times().begin(), animation.times().end());
  // Only the moving vertices are keyed on the device; the static ones are uploaded once into
  // `positions` and never written by the per-frame interpolation.
  movingVertices = animation.movingVertexCount();
  keyframes = DeviceBuffer<float>(animation.motion(), stream);
  movingIds = DeviceBuffer<uint32_t>(animation.movingVertices(), stream);
  hostRest.assign(animation.restPositions().begin(), animation.restPositions().end());
  const auto idx = animation.indices();
  indices = DeviceBuffer<uint32_t>(idx, stream);
  hostIndices.assign(idx.begin(), idx.end());
  positions.resize(std::size_t(vertices) * 3);
  if (!hostRest.empty()) positions.upload(std::span<const float>(hostRest), stream);
  if (!animation.allMoving()) movingVertexIds.assign(animation.movingVertices().begin(), animation.movingVertices().end());
  trees.reserve(set.trees.size());
  for (std::size_t i = 0; i < set.trees.size(); ++i) {
    const Objective& wideObjective = set.builds.empty() ? config.wideObjective : set.builds[i].objective;
    uploadTree(set.trees[i], std::move(topologies[i]), wideObjective);
  }
  ranges = set.ranges;
  woop.resize(triangles);
  words.resize(8);
  CUDA_CHECK(cudaStreamSynchronize(stream));
}

void GpuRuntime::Impl::uploadTree(const FlatBvh& tree, FlatBvh topologyOfTree, const Objective& wideObjective) {
  DeviceTree& d = trees.emplace_back();
  d.topology = std::move(topologyOfTree);
  const FlatBvh& topology = d.topology;

  const detail::RefitTopology refit = detail::refitTopology(topology);
  const std::vector<uint32_t>& parent = refit.parent;
  const std::vector<detail::LeafRecord>& leafRecords = refit.leaves;
  d.nodes = DeviceBuffer<GpuBvhNode>(std::span<const GpuBvhNode>(topology.nodes), stream);
  d.nodeParent = DeviceBuffer<uint32_t>(std::span<const uint32_t>(parent), stream);
  d.counters.resize(topology.interiorCount);
  d.triIndex = DeviceBuffer<uint32_t>(std::span<const uint32_t>(topology.triIndex), stream);
  // The refit and Woop pass of the binary layout stream the slots' vertex ids (the compressed
  // layout keeps its own, in its slot order).
  std::vector<uint32_t> slotVertices;
  if (config.layout == Layout::Bvh2) {
    slotVertices = slotVertexIndices(topology.triIndex, hostIndices, "GPU runtime");
    d.slotVertices = DeviceBuffer<uint32_t>(std::span<const uint32_t>(slotVertices), stream);
  }
  d.leaves = DeviceBuffer<detail::LeafRecord>(std::span<const detail::LeafRecord>(leafRecords), stream);
  std::vector<detail::LeafRecord> movingLeafRecords;
  std::vector<uint32_t> staticChildren, movingSlotList;
  if (config.skipStaticSubtrees && config.layout == Layout::Bvh2 && !movingVertexIds.empty() &&
      topology.interiorCount > 0) {
    const MovingParts parts = findMovingParts(topology, hostIndices, movingVertexIds, vertices);
    if (parts.movingSlots < topology.triangleCount()) {
      d.hasStaticParts = true;
      const auto slotsMove = [&](uint32_t first, uint32_t count) {
        return std::any_of(parts.slotMoves.begin() + first, parts.slotMoves.begin() + first + count,
                           [](uint8_t m) { return m != 0; });
      };
      for (const detail::LeafRecord& leaf : leafRecords)
        if (slotsMove(leaf.first, leaf.count)) movingLeafRecords.push_back(leaf);
      staticChildren.assign(topology.interiorCount, 0);
      for (uint32_t i = 0; i < topology.interiorCount; ++i) {
        const GpuBvhNode& n = topology.nodes[i];
        for (int c = 0; c < 2; ++c) {
          const int32_t ref = n.childRef(c);
          const bool moves = isLeafRef(ref) ? slotsMove(leafFirstSlot(ref), n.childCount(c))
                                            : parts.nodeMoves[uint32_t(ref)] != 0;
          staticChildren[i] += moves ? 0u : 1u;
        }
      }
      for (uint32_t s = 0; s < topology.triangleCount(); ++s)
        if (parts.slotMoves[s]) movingSlotList.push_back(s);
      d.movingLeaves = DeviceBuffer<detail::LeafRecord>(std::span<const detail::LeafRecord>(movingLeafRecords), stream);
      d.staticChildren = DeviceBuffer<uint32_t>(std::span<const uint32_t>(staticChildren), stream);
      d.movingSlots = DeviceBuffer<uint32_t>(std::span<const uint32_t>(movingSlotList), stream);
    }
  }
  detail::RootInfo r;
  r.box = topology.rootBoxes[0];
  r.ref = topology.rootRef;
  r.count = topology.rootCount;
  r.interiorCount = topology.interiorCount;
  r.depth = topology.depth;
  d.root = DeviceBuffer<detail::RootInfo>(std::span<const detail::RootInfo>(&r, 1), stream);
  if (config.layout == Layout::Cwbvh) d.cwbvh = uploadCwbvh(tree, hostIndices, wideObjective, stream);
  // The host vectors above are freed when this returns: finish their uploads first.
  CUDA_CHECK(cudaStreamSynchronize(stream));
}

GpuRuntime::Impl::~Impl() { releaseDevice(); }

void GpuRuntime::Impl::releaseDevice() noexcept {
  if (stream) cudaStreamSynchronize(stream);
  for (DeviceTree& t : trees) {
    destroy(t.updateGraph);
    destroy(t.partialUpdateGraph);
  }
  for (auto& g : rebuildGraphs) destroy(g.graph);
  for (auto& g : shutterGraphs) destroy(g.graph);
  if (sideStream) cudaStreamSynchronize(sideStream);
  if (stream) cudaStreamDestroy(std::exchange(stream, nullptr));
  if (sideStream) cudaStreamDestroy(std::exchange(sideStream, nullptr));
}

void GpuRuntime::Impl::launch(const CapturedGraph& g) {
  if (g.interpolation.node) detail::setInterpolationParams(g.exec, g.interpolation, frame);
  CUDA_CHECK(cudaGraphLaunch(g.exec, stream));
}

void GpuRuntime::Impl::destroy(CapturedGraph& g) noexcept {
  if (g.exec) cudaGraphExecDestroy(std::exchange(g.exec, nullptr));
  if (g.graph) cudaGraphDestroy(std::exchange(g.graph, nullptr));
  g.interpolation = {};
}

void GpuRuntime::Impl::setFrame(double time) {
  const auto [k, alpha] = anim::keyframeBlend(times, time);
  frame = detail::blendFrame(k, alpha, movingVertices);
}

void GpuRuntime::Impl::enqueueInterpolation() {
  events.record(0, stream);
  detail::launchInterpolateFrame(keyframes.data(), movingIds.size() ? movingIds.data() : nullptr, frame,
                                 positions.data(), movingVertices, stream);
  events.record(1, stream);
}

void GpuRuntime::Impl::restoreStaticPositions() {
  if (restInPlace) return;
  if (!hostRest.empty()) positions.upload(std::span<const float>(hostRest), stream);
  restInPlace = true;
}

detail::VertexTriangles detail::vertexTriangles(std::span<const uint32_t> indices, uint32_t vertexCount) {
  VertexTriangles lists;
  lists.offsets.assign(std::size_t(vertexCount) + 1, 0);
  for (uint32_t v : indices) ++lists.offsets[v + 1];
  for (uint32_t v = 0; v < vertexCount; ++v) lists.offsets[v + 1] += lists.offsets[v];
  lists.triangles.resize(indices.size());
  std::vector<uint32_t> fill(lists.offsets.begin(), lists.offsets.end() - 1);
  for (std::size_t i = 0; i < indices.size(); ++i) lists.triangles[fill[indices[i]]++] = uint32_t(i / 3);
  return lists;
}

void GpuRuntime::Impl::buildVertexTriangles() {
  const detail::VertexTriangles lists = detail::vertexTriangles(hostIndices, vertices);
  vertexTriOffsets = DeviceBuffer<uint32_t>(std::span<const uint32_t>(lists.offsets), stream);
  vertexTris = DeviceBuffer<uint32_t>(std::span<const uint32_t>(lists.triangles), stream);
  normals.resize(std::size_t(vertices) * 3);
}

// The 8-wide collapse over all frames of the given tree for the objective (WideCollapser), its
// compressed layout, and what the per-frame refit needs on the device.
std::unique_ptr<GpuRuntime::Impl::Cwbvh> GpuRuntime::Impl::uploadCwbvh(const FlatBvh& tree,
                                                                         std::span<const uint32_t> indices,
                                                                         const Objective& objective,
                                                                         cudaStream_t stream) {
  auto cwbvh = std::make_unique<Cwbvh>();
  Cwbvh& c = *cwbvh;
  c.host = buildCwbvh(tree, objective);
  c.nodes = DeviceBuffer<CwbvhNode>(std::span<const CwbvhNode>(c.host.nodes), stream);
  c.nodeBoxes.resize(c.host.nodes.size());
  c.triIndex = DeviceBuffer<uint32_t>(std::span<const uint32_t>(c.host.triIndex), stream);
  const std::vector<uint32_t> slotVertices = slotVertexIndices(c.host.triIndex, indices, "GPU runtime");
  c.slotVertices = DeviceBuffer<uint32_t>(std::span<const uint32_t>(slotVertices), stream);
  c.refit = detail::makeCwbvhRefitPlan(c.host, stream);
  const detail::RootInfo r = detail::cwbvhRoot(c.host);
  c.root = DeviceBuffer<detail::RootInfo>(std::span<const detail::RootInfo>(&r, 1), stream);
  CUDA_CHECK(cudaStreamSynchronize(stream));  // before slotVertices and r go
  return cwbvh;
}

detail::TraceScene GpuRuntime::Impl::scene() const {
  if (const detail::GpuCwbvhConverter* wide = tracingRebuilt ? rebuilder->wide() : nullptr) {
    detail::TraceScene s;  // the rebuilt tree in the compressed layout: always a root node
    s.woop = woop.data();
    s.triIndex = wide->triIndex();
    s.indices = indices.data();
    s.positions = positions.data();
    s.root = rebuilder->root();
    s.cwbvhNodes = wide->nodes();
    return s;
  }
  if (const Cwbvh* cwbvh = tree().cwbvh.get(); cwbvh && !tracingRebuilt) {
    detail::TraceScene s;
    s.woop = woop.data();
    s.triIndex = cwbvh->triIndex.data();
    s.indices = indices.data();
    s.positions = positions.data();
    s.root = cwbvh->root.data();
    s.cwbvhNodes = cwbvh->nodes.data();
    s.cwbvhRootRef = cwbvh->host.rootRef;
    s.cwbvhRootCount = cwbvh->host.rootCount;
    return s;
  }
  detail::TraceScene s;
  s.nodes = tracingRebuilt ? rebuilder->nodes() : tree().nodes.data();
  s.woop = woop.data();
  s.triIndex = tracingRebuilt ? rebuilder->triIndex() : tree().triIndex.data();
  s.indices = indices.data();
  s.positions = positions.data();
  s.root = tracingRebuilt ? rebuilder->root() : tree().root.data();
  return s;
}

void GpuRuntime::Impl::requireTraceable() const {
  if (!woopValid)
    throw tsah::ConfigError("GPU runtime: nothing to trace yet (call update/updateAt, or rebuild with Woop triangles)");
}

bool GpuRuntime::Impl::partialUpdatePossible() const {
  const DeviceTree& t = tree();
  return t.hasStaticParts && t.staticBoxesValid && woopTree == int(current) && restInPlace && !t.cwbvh;
}

void GpuRuntime::Impl::enqueueRefitAndWoop(bool movingOnly) {
  // The Woop pass (bandwidth-bound) runs on the side stream beside the refit (latency-bound: a
  // chain of small launches or atomics up the tree); both only read the positions. Events 12 and
  // 13 fork and join the side stream; 2 follows the refit, 3 both.
  DeviceTree& t = tree();
  Cwbvh* c = t.cwbvh.get();
  events.mark(12, stream);
  events.streamWait(12, sideStream);
  if (movingOnly)
    detail::launchMovingSlotWoop(t.movingSlots.data(), uint32_t(t.movingSlots.size()), t.slotVertices.data(),
                                 positions.data(), woop.data(), sideStream);
  else
    detail::launchSlotWoop(c ? c->slotVertices.data() : t.slotVertices.data(), triangles, positions.data(),
                           woop.data(), sideStream);
  events.mark(13, sideStream);
  if (c) {  // refit + re-quantize the compressed layout
    detail::launchCwbvhRefit(c->refit, c->nodes.data(), c->nodeBoxes.data(), c->slotVertices.data(), positions.data(),
                             c->root.data(), stream);
  } else if (movingOnly) {  // a static child counts as arrived: the moving one carries on at once
    CUDA_CHECK(cudaMemcpyAsync(t.counters.data(), t.staticChildren.data(), t.staticChildren.bytes(),
                               cudaMemcpyDeviceToDevice, stream));
    detail::launchRefit(t.nodes.data(), t.nodeParent.data(), t.movingLeaves.data(), uint32_t(t.movingLeaves.size()),
                        t.slotVertices.data(), positions.data(), t.counters.data(), t.root.data(), stream);
  } else {
    t.counters.fillBytes(0, stream);
    detail::launchRefit(t.nodes.data(), t.nodeParent.data(), t.leaves.data(), uint32_t(t.leaves.size()),
                        t.slotVertices.data(), positions.data(), t.counters.data(), t.root.data(), stream);
  }
  events.record(2, stream);
  events.streamWait(13, stream);
  events.record(3, stream);
}

UpdateTimings GpuRuntime::Impl::finishUpdate(uint32_t slotsUpdated) {
  UpdateTimings timings;
  timings.slotsUpdated = slotsUpdated;
  events.wait(3);
  timings.interpolateMs = events.ms(0, 1);
  timings.refitMs = events.ms(1, 2);
  timings.woopMs = events.ms(2, 3);
  markUpdated();
  return timings;
}

void GpuRuntime::Impl::markUpdated() {
  tracingRebuilt = false;
  frameTree = int(current);
  woopValid = true;
  shutterKeys = 0;  // an update ends a blurred frame (updateShutter sets its keys after its updates)
  storedPartCount = 0;
}

namespace {

TreeSet setOfOne(const FlatBvh& tree, const anim::Animation& animation) {
  TreeSet set;
  set.trees = {tree};
  set.ranges = {{animation.startTime(), animation.endTime()}};
  return set;
}

}  // namespace

GpuRuntime::GpuRuntime(const FlatBvh& tree, const anim::Animation& animation, Config config)
    : impl_(std::make_unique<Impl>(setOfOne(tree, animation), animation, config)) {}
GpuRuntime::GpuRuntime(const TreeSet& set, const anim::Animation& animation, Config config)
    : impl_(std::make_unique<Impl>(set, animation, config)) {}
GpuRuntime::GpuRuntime(const FlatBvh& tree, const anim::Animation& animation)
    : GpuRuntime(tree, animation, Config{}) {}
GpuRuntime::~GpuRuntime() = default;

uint32_t GpuRuntime::selectTreeAt(double time) {
  Impl& m = *impl_;
  m.current = treeIndexAt(m.ranges, time);
  return m.current;
}

uint32_t GpuRuntime::treeCount() const { return static_cast<uint32_t>(impl_->trees.size()); }
uint32_t GpuRuntime::currentTree() const { return impl_->current; }

UpdateTimings GpuRuntime::updateAt(double time) {
  Impl& m = *impl_;
  m.throwRefusedDeviceUpdate();
  m.current = treeIndexAt(m.ranges, time);
  return m.refitAt(time);
}

UpdateTimings GpuRuntime::Impl::refitAt(double time) {
  Impl& m = *this;
  m.setFrame(time);
  m.restoreStaticPositions();
  const bool movingOnly = m.partialUpdatePossible();
  auto enqueue = [&] {
    m.enqueueInterpolation();
    m.enqueueRefitAndWoop(movingOnly);
  };
  Impl::DeviceTree& t = m.tree();
  if (m.config.useGraphs) {
    Impl::CapturedGraph& graph = movingOnly ? t.partialUpdateGraph : t.updateGraph;
    if (!graph.exec) graph = m.capture(enqueue);
    m.launch(graph);
  } else {
    enqueue();
  }
  const UpdateTimings timings = m.finishUpdate(movingOnly ? uint32_t(t.movingSlots.size()) : m.triangles);
  // The static vertices were at rest: the static subtrees' boxes and triangles stay valid.
  t.staticBoxesValid = true;
  m.woopTree = int(m.current);
  return timings;
}

void GpuRuntime::Impl::uploadPositions(std::span<const float> given) {
  if (given.size() != std::size_t(vertices) * 3)
    throw tsah::DataError("GPU runtime: got " + std::to_string(given.size()) + " coordinates, expected " +
                          std::to_string(std::size_t(vertices) * 3));
  events.record(0, stream);
  positions.upload(given, stream);
  restInPlace = false;
  events.record(1, stream);
}

UpdateTimings GpuRuntime::update(std::span<const float> positions) {
  Impl& m = *impl_;
  m.throwRefusedDeviceUpdate();
  m.uploadPositions(positions);
  m.enqueueRefitAndWoop();
  // The caller's positions may move the static vertices too: the next updateAt refits everything.
  m.tree().staticBoxesValid = false;
  m.woopTree = -1;
  return m.finishUpdate(m.triangles);
}

namespace {

bool sameOptions(const RebuildOptions& a, const RebuildOptions& b) {
  return a.method == b.method && a.collapse == b.collapse && a.maxLeafSize == b.maxLeafSize &&
         a.cost.ct == b.cost.ct && a.cost.ci == b.cost.ci && a.woop == b.woop &&
         a.wideMergeTriangles == b.wideMergeTriangles;
}

}  // namespace

RebuildTimings GpuRuntime::rebuildAt(double time, const RebuildOptions& options) {
  Impl& m = *impl_;
  m.throwRefusedDeviceUpdate();
  if (options.maxLeafSize == 0) throw tsah::ConfigError("GPU rebuild: maxLeafSize must be at least 1");
  if (!m.rebuilder) m.rebuilder = std::make_unique<detail::GpuRebuilder>(m.triangles, m.config.layout);
  m.setFrame(time);
  m.restoreStaticPositions();
  m.woopValid = false;
  m.woopTree = -1;  // the rebuild writes its own triangles into woop
  m.tracingRebuilt = true;
  m.shutterKeys = 0;
  auto enqueue = [&] {
    m.enqueueInterpolation();
    m.rebuilder->enqueue(m.indices.data(), m.positions.data(), options, m.woop.data(), m.stream);
  };
  if (m.config.useGraphs) {
    auto it = std::find_if(m.rebuildGraphs.begin(), m.rebuildGraphs.end(),
                           [&](const Impl::RebuildGraph& g) { return sameOptions(g.options, options); });
    if (it == m.rebuildGraphs.end()) {
      m.rebuildGraphs.push_back({options, m.capture(enqueue)});
      it = m.rebuildGraphs.end() - 1;
    }
    m.launch(it->graph);
  } else {
    enqueue();
  }
  RebuildTimings timings = m.rebuilder->collect(options);
  timings.interpolateMs = m.events.ms(0, 1);
  m.woopValid = options.woop;
  return timings;
}

RebuildTimings GpuRuntime::rebuild(std::span<const float> positions, const RebuildOptions& options) {
  Impl& m = *impl_;
  m.throwRefusedDeviceUpdate();
  m.uploadPositions(positions);
  if (!m.rebuilder) m.rebuilder = std::make_unique<detail::GpuRebuilder>(m.triangles, m.config.layout);
  m.woopValid = false;
  m.woopTree = -1;
  m.tree().staticBoxesValid = false;
  m.tracingRebuilt = true;
  m.shutterKeys = 0;
  RebuildTimings timings = m.rebuilder->build(m.indices.data(), m.positions.data(), options, m.woop.data(), m.stream);
  timings.interpolateMs = m.events.ms(0, 1);
  m.woopValid = options.woop;
  return timings;
}

bool GpuRuntime::tracingRebuiltTree() const { return impl_->tracingRebuilt; }
uint32_t GpuRuntime::triangleCount() const { return impl_->triangles; }
uint32_t GpuRuntime::vertexCount() const { return impl_->vertices; }
const DeviceInfo& GpuRuntime::device() const { return impl_->device; }
const GpuRuntime::Config& GpuRuntime::config() const { return impl_->config; }

std::vector<float> GpuRuntime::downloadPositions() const { return impl_->positions.download(impl_->stream); }

std::vector<WoopTriangle> GpuRuntime::downloadWoop() const { return impl_->woop.download(impl_->stream); }

std::vector<CwbvhNode> GpuRuntime::downloadCwbvhNodes() const {
  if (impl_->tracingRebuilt && impl_->rebuilder->wide()) return downloadRebuiltCwbvh().nodes;
  const Impl::Cwbvh* cwbvh = impl_->tree().cwbvh.get();
  if (!cwbvh) throw tsah::ConfigError("GPU runtime: the tree is not in the compressed wide layout");
  return cwbvh->nodes.download(impl_->stream);
}

FlatBvh GpuRuntime::downloadTree() const {
  const Impl& m = *impl_;
  if (m.tree().cwbvh && !m.tracingRebuilt)
    throw tsah::ConfigError(
        "GPU runtime: downloadTree gives the binary layout; this runtime traces the compressed one");
  if (m.tracingRebuilt) return flattenBvh(downloadRebuiltTree());
  FlatBvh flat = m.tree().topology;
  flat.nodes = m.tree().nodes.download(m.stream);
  flat.rootBoxes = {m.tree().root.download(m.stream)[0].box};
  return flat;
}

const detail::GpuRebuilder& GpuRuntime::Impl::lastRebuild() const {
  if (!rebuilder || !rebuilder->built()) throw tsah::ConfigError("GPU runtime: no tree has been rebuilt");
  return *rebuilder;
}

Bvh GpuRuntime::downloadRebuiltTree() const { return impl_->lastRebuild().download(impl_->stream); }

CwbvhTree GpuRuntime::downloadRebuiltCwbvh() const {
  const detail::GpuRebuilder& rebuilt = impl_->lastRebuild();
  if (!rebuilt.wide()) throw tsah::ConfigError("GPU runtime: rebuilt trees are in the binary layout (layout bvh2)");
  CwbvhTree t = rebuilt.wide()->download(impl_->stream);
  t.rootBox = bounds();
  return t;
}

FlatBvh GpuRuntime::downloadRebuiltArrays() const { return impl_->lastRebuild().downloadArrays(impl_->stream); }

Aabb GpuRuntime::bounds() const {
  const Impl& m = *impl_;
  detail::RootInfo r;
  CUDA_CHECK(cudaMemcpyAsync(&r, m.scene().root, sizeof r, cudaMemcpyDeviceToHost, m.stream));
  CUDA_CHECK(cudaStreamSynchronize(m.stream));
  return r.box;
}

namespace {

template <typename Result>
std::vector<Result> traceInstant(GpuRuntime::Impl& m, std::span<const Ray> rays, RayPassStats* stats) {
  m.requireTraceable();
  return traceHostRays<Result>(
      m, rays, stats, [&](uint32_t) { m.words.fillBytes(0, m.stream); },
      [&](uint32_t count, Hit* hits, uint8_t* occluded) {
        detail::launchTrace(m.scene(), m.rays.data(), count, hits, occluded, m.words.data(), m.traceLaunch(), m.stream);
      });
}

}  // namespace

std::vector<Hit> GpuRuntime::closestHits(std::span<const Ray> rays, RayPassStats* stats) {
  return traceInstant<Hit>(*impl_, rays, stats);
}

std::vector<uint8_t> GpuRuntime::anyHits(std::span<const Ray> rays, RayPassStats* stats) {
  return traceInstant<uint8_t>(*impl_, rays, stats);
}

}  // namespace tsah::cuda
