// GpuRuntime's motion blur from host positions: the current tree refitted at every key of a shutter,
// one copy of the traced tree's nodes, root and positions per key (docs/cuda-runtime.md).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"
#include "blurred_trace.hpp"
#include "cwbvh_kernels.hpp"
#include "kernels.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/pipeline.hpp"
#include "runtime_impl.hpp"

namespace tsah::cuda {

void GpuRuntime::Impl::requireKey(uint32_t key) const {
  if (shutterKeys == 0) throw tsah::ConfigError("GPU runtime: the frame is not blurred (no updateShutter)");
  if (key >= shutterKeys)
    throw tsah::ConfigError("GPU runtime: key " + std::to_string(key) + " of a shutter with " +
                            std::to_string(shutterKeys) + " keys");
}

void GpuRuntime::Impl::requireBinaryLayout() const {
  if (config.layout != Layout::Bvh2)
    throw tsah::ConfigError("GPU runtime: motion blur traces the binary layout on the GPU (layout bvh2, not " +
                            std::string(name(config.layout)) + ")");
}

// Runs refitKey(k) for every key and keeps each key's nodes, root and positions.
template <typename RefitKey>
UpdateTimings GpuRuntime::Impl::refitKeys(std::span<const float> keyTimes, RefitKey&& refitKey) {
  requireBinaryLayout();
  const auto keys = static_cast<uint32_t>(keyTimes.size());
  DeviceTree& t = tree();
  const std::size_t interior = t.topology.interiorCount, coords = std::size_t(vertices) * 3;
  keyNodes.reserve(std::size_t(keys) * interior);
  keyRootBoxes.reserve(keys);
  keyPositions.reserve(std::size_t(keys) * coords);
  keySlotsReady = 0;  // the slots get the caller's positions of every vertex
  UpdateTimings total;
  for (uint32_t k = 0; k < keys; ++k) {
    // Each key is a whole update (bit-identical to CpuRuntime::update at its positions), kept.
    const UpdateTimings one = refitKey(k);
    total.interpolateMs += one.interpolateMs;
    total.refitMs += one.refitMs;
    total.woopMs += one.woopMs;
    // Keeping the key (events 14 and 15: free outside an update and a render) counts in the refit.
    events.record(14, stream);
    if (interior)
      CUDA_CHECK(cudaMemcpyAsync(keyNodes.data() + k * interior, t.nodes.data(), interior * sizeof(GpuBvhNode),
                                 cudaMemcpyDeviceToDevice, stream));
    CUDA_CHECK(cudaMemcpyAsync(keyRootBoxes.data() + k, &t.root.data()->box, sizeof(Aabb), cudaMemcpyDeviceToDevice,
                               stream));
    CUDA_CHECK(cudaMemcpyAsync(keyPositions.data() + k * coords, positions.data(), coords * sizeof(float),
                               cudaMemcpyDeviceToDevice, stream));
    events.record(15, stream);
    events.wait(15);
    total.refitMs += events.ms(14, 15);
  }
  enqueueBlurredLayout(keys, false);
  shutterKeys = keys;
  shutterKeyTimes.assign(keyTimes.begin(), keyTimes.end());
  keyFractions.reserve(keys);
  keyFractions.upload(keyTimes, stream);
  CUDA_CHECK(cudaStreamSynchronize(stream));
  return total;
}

void GpuRuntime::Impl::enqueueBlurredLayout(uint32_t keys, bool withInstantState) {
  DeviceTree& t = tree();
  const uint32_t interior = t.topology.interiorCount;
  blurNodes.reserve(std::size_t(keys - 1) * interior);
  blurTriangles.reserve(std::size_t(keys) * triangles);
  detail::BlurredLayoutSources from;
  from.keyNodes = keyNodes.data();
  from.nodeCount = interior;
  from.keyPositions = keyPositions.data();
  from.keyStride = uint64_t(vertices) * 3;
  from.slotVertices = t.slotVertices.data();
  from.slots = triangles;
  from.keyCount = keys;
  if (withInstantState) {
    from.keyRoots = keyRoots.data();
    from.keyRootBoxes = keyRootBoxes.data();
    from.lastNodes = t.nodes.data();
    from.lastRoot = t.root.data();
    from.lastPositions = positions.data();
  }
  detail::launchBuildBlurredLayout(from, blurNodes.data(), blurTriangles.data(), stream);
}

UpdateTimings GpuRuntime::updateShutter(std::span<const float> keyTimes,
                                        std::span<const std::span<const float>> keyPositions) {
  Impl& m = *impl_;
  motion::checkKeyTimes(keyTimes, keyPositions.size(), "GPU runtime: updateShutter: ");
  if (keyTimes.size() == 1) return update(keyPositions[0]);
  for (std::span<const float> p : keyPositions)  // before anything is refitted
    if (p.size() != std::size_t(m.vertices) * 3)
      throw tsah::DataError("GPU runtime: updateShutter got " + std::to_string(p.size()) +
                            " coordinates for a key, expected " + std::to_string(std::size_t(m.vertices) * 3));
  return m.refitKeys(keyTimes, [&](uint32_t k) { return update(keyPositions[k]); });
}

UpdateTimings GpuRuntime::updateShutterAt(double open, double close) {
  Impl& m = *impl_;
  if (!(open <= close))
    throw tsah::ConfigError("GPU runtime: updateShutterAt: the shutter opens at " + std::to_string(open) +
                            ", after it closes at " + std::to_string(close));
  // A tree set: each ray by the tree of its time, one part per tree the shutter crosses.
  const std::vector<ShutterStretch> parts = shutterStretches(m.times, open, close, m.ranges);
  m.current = parts[0].tree;
  if (parts[0].keys.size() == 1) return m.refitAt(open);
  m.requireBinaryLayout();
  UpdateTimings total;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    m.current = parts[p].tree;
    const UpdateTimings t = m.refitAnimationKeys(parts[p].keys, parts[p].fractions);
    total.interpolateMs += t.interpolateMs;
    total.refitMs += t.refitMs;
    total.woopMs += t.woopMs;
    total.slotsUpdated = t.slotsUpdated;
    if (p + 1 < parts.size()) m.storePart(uint32_t(p));
  }
  m.storedPartCount = uint32_t(parts.size() - 1);
  if (m.storedPartCount > 0) {
    std::vector<detail::BlurredPart> later;
    for (uint32_t p = 1; p < parts.size(); ++p) later.push_back(m.blurredShutterPart(p));
    m.laterParts.reserve(later.size());
    m.laterParts.upload(later, m.stream);
    CUDA_CHECK(cudaStreamSynchronize(m.stream));  // `later` is pageable host memory
  }
  return total;
}

void GpuRuntime::Impl::storePart(uint32_t p) {
  if (storedParts.size() <= p) storedParts.resize(p + 1);
  StoredPart& s = storedParts[p];
  s.tree = current;
  s.keys = shutterKeys;
  s.start = shutterKeyTimes.front();
  std::swap(s.keyNodes, keyNodes);
  std::swap(s.keyRootBoxes, keyRootBoxes);
  std::swap(s.keyPositions, keyPositions);
  std::swap(s.keyFractions, keyFractions);
  std::swap(s.blurNodes, blurNodes);
  std::swap(s.blurTriangles, blurTriangles);
  keySlotsReady = 0;  // the slots now hold another part's buffers
  keySlotsTree = -1;
}

UpdateTimings GpuRuntime::Impl::refitAnimationKeys(std::span<const double> keyTimes, std::span<const float> fractions) {
  const auto keys = static_cast<uint32_t>(keyTimes.size());
  DeviceTree& t = tree();
  const std::size_t interior = t.topology.interiorCount, coords = std::size_t(vertices) * 3;
  // Every key slot starts from the rest positions of the static vertices (the batch moves the others).
  restoreStaticPositions();
  if (keyNodes.size() < std::size_t(keys) * interior || keyPositions.size() < std::size_t(keys) * coords ||
      keySlotsTree != int(current))
    keySlotsReady = 0;  // reallocated, or another tree's references
  keyNodes.reserve(std::size_t(keys) * interior);
  keyRootBoxes.reserve(keys);
  keyPositions.reserve(std::size_t(keys) * coords);
  keyCounters.reserve(std::size_t(keys) * interior);
  keyRoots.reserve(keys);
  keyFrames.reserve(keys);
  keyFractions.reserve(keys);
  blurNodes.reserve(std::size_t(keys - 1) * interior);
  blurTriangles.reserve(std::size_t(keys) * triangles);
  std::vector<detail::FrameParams> blends(keys);
  for (uint32_t k = 0; k < keys; ++k) {
    setFrame(keyTimes[k]);  // leaves the last key's blend in `frame`, as updateAt(last) would
    blends[k] = frame;
  }
  keyFrames.upload(blends, stream);
  keyFractions.upload(fractions, stream);
  // A slot starts as the instant state once: the static vertices' rest positions (the batch moves
  // the others) and the nodes' child references (the batch rewrites the boxes).
  for (uint32_t k = keySlotsReady; k < keys; ++k) {
    CUDA_CHECK(cudaMemcpyAsync(keyPositions.data() + k * coords, positions.data(), coords * sizeof(float),
                               cudaMemcpyDeviceToDevice, stream));
    if (interior)
      CUDA_CHECK(cudaMemcpyAsync(keyNodes.data() + k * interior, t.nodes.data(), interior * sizeof(GpuBvhNode),
                                 cudaMemcpyDeviceToDevice, stream));
  }
  keySlotsReady = std::max(keySlotsReady, keys);
  keySlotsTree = int(current);
  if (config.useGraphs) {
    // A graph holds the key count, the tree's sizes and every buffer's address: one per key count
    // and tree (a shutter that sometimes spans a keyframe alternates two), captured again when a
    // buffer has grown.
    const Impl::ShutterGraphArgs args{keys,
                                      current,
                                      {keyNodes.data(), keyRootBoxes.data(), keyPositions.data(), keyCounters.data(),
                                       keyRoots.data(), keyFrames.data(), blurNodes.data(), blurTriangles.data()}};
    auto it = std::find_if(shutterGraphs.begin(), shutterGraphs.end(), [&](const Impl::ShutterGraph& g) {
      return g.args.keys == keys && g.args.tree == current;
    });
    if (it == shutterGraphs.end()) it = shutterGraphs.insert(shutterGraphs.end(), Impl::ShutterGraph{});
    if (!it->graph.exec || !(it->args == args)) {
      destroy(it->graph);
      it->graph = capture([&] { enqueueShutterRefit(keys); });
      it->args = args;
    }
    launch(it->graph);
  } else {
    enqueueShutterRefit(keys);
  }
  events.wait(3);
  UpdateTimings timings;
  timings.interpolateMs = events.ms(0, 1);
  timings.refitMs = events.ms(1, 2);
  timings.woopMs = events.ms(2, 3);
  timings.slotsUpdated = triangles;
  markUpdated();
  // The instant state is a full update at the last key: static subtrees and every Woop triangle in
  // place, the static vertices at rest (the key slots hold them so).
  t.staticBoxesValid = true;
  woopTree = int(current);
  shutterKeys = keys;
  shutterKeyTimes.assign(fractions.begin(), fractions.end());
  return timings;
}

void GpuRuntime::Impl::enqueueShutterRefit(uint32_t keys) {
  DeviceTree& t = tree();
  const std::size_t interior = t.topology.interiorCount, coords = std::size_t(vertices) * 3;
  detail::BatchStrides strides;
  strides.positions = coords;
  strides.nodes = interior;
  strides.counters = interior;
  events.record(0, stream);
  detail::launchBatchInterpolate(keyframes.data(), movingIds.size() ? movingIds.data() : nullptr, keyFrames.data(),
                                 keyPositions.data(), movingVertices, keys, coords, stream);
  events.record(1, stream);
  if (interior) CUDA_CHECK(cudaMemsetAsync(keyCounters.data(), 0, std::size_t(keys) * interior * sizeof(uint32_t), stream));
  detail::launchBatchRefit(keyNodes.data(), t.nodeParent.data(), t.leaves.data(), uint32_t(t.leaves.size()),
                           t.slotVertices.data(), keyPositions.data(), keyCounters.data(), keyRoots.data(), keys,
                           strides, stream);
  events.record(2, stream);
  // The blurred layout, and the instant state from the last key (refitted once, in the batch): its
  // nodes, root box and positions in the same launch, its Woop triangles beside it on the side
  // stream (events 12 and 13).
  const uint32_t last = keys - 1;
  events.mark(12, stream);
  events.streamWait(12, sideStream);
  detail::launchSlotWoop(t.slotVertices.data(), triangles, keyPositions.data() + last * coords, woop.data(), sideStream);
  events.mark(13, sideStream);
  enqueueBlurredLayout(keys, true);
  events.streamWait(13, stream);
  events.record(3, stream);
}

bool GpuRuntime::blurred() const { return impl_->shutterKeys >= 2; }
uint32_t GpuRuntime::shutterKeyCount() const {
  const Impl& m = *impl_;
  uint32_t keys = m.shutterKeys;
  for (uint32_t p = 0; p < m.storedPartCount; ++p) keys += m.storedParts[p].keys;
  return keys;
}

FlatBvh GpuRuntime::downloadKeyTree(uint32_t key) const {
  const Impl& m = *impl_;
  m.requireKey(key);
  FlatBvh flat = m.tree().topology;
  const std::size_t interior = flat.interiorCount;
  flat.nodes.resize(interior);
  if (interior)
    CUDA_CHECK(cudaMemcpyAsync(flat.nodes.data(), m.keyNodes.data() + key * interior, interior * sizeof(GpuBvhNode),
                               cudaMemcpyDeviceToHost, m.stream));
  flat.rootBoxes.resize(1);
  CUDA_CHECK(cudaMemcpyAsync(flat.rootBoxes.data(), m.keyRootBoxes.data() + key, sizeof(Aabb), cudaMemcpyDeviceToHost,
                             m.stream));
  CUDA_CHECK(cudaStreamSynchronize(m.stream));
  return flat;
}

std::vector<float> GpuRuntime::downloadKeyPositions(uint32_t key) const {
  const Impl& m = *impl_;
  m.requireKey(key);
  const std::size_t coords = std::size_t(m.vertices) * 3;
  std::vector<float> out(coords);
  CUDA_CHECK(cudaMemcpyAsync(out.data(), m.keyPositions.data() + key * coords, coords * sizeof(float),
                             cudaMemcpyDeviceToHost, m.stream));
  CUDA_CHECK(cudaStreamSynchronize(m.stream));
  return out;
}

namespace {

// A part's key arrays and layout (the last part's are the runtime's members, the others stored).
struct PartArrays {
  const GpuRuntime::Impl::DeviceTree& tree;
  uint32_t keys;
  const GpuBvhNode* keyNodes;
  const Aabb* keyRootBoxes;
  const float *keyPositions, *keyFractions;
  const motion::BlurredNodeSegment* blurNodes;
  const detail::KeyTriangle* blurTriangles;
};

detail::BlurredPart partView(const PartArrays& a, const GpuRuntime::Impl& m) {
  const FlatBvh& topology = a.tree.topology;
  detail::BlurredPart part;
  MotionBvhView& view = part.view;
  view.keyNodes = a.keyNodes;
  view.keyRootBoxes = a.keyRootBoxes;
  view.keyPositions = a.keyPositions;
  view.keyTimes = a.keyFractions;
  view.keyCount = a.keys;
  view.nodeCount = topology.interiorCount;
  view.vertexCount = m.vertices;
  view.triIndex = a.tree.triIndex.data();
  view.indices = m.indices.data();
  view.rootRef = topology.rootRef;
  view.rootCount = topology.rootCount;
  detail::BlurredLayout& l = part.layout;
  l.nodes = a.blurNodes;
  l.triangles = a.blurTriangles;
  l.keyRootBoxes = a.keyRootBoxes;
  l.keyTimes = a.keyFractions;
  l.triIndex = a.tree.triIndex.data();
  l.keyCount = a.keys;
  l.rootRef = topology.rootRef;
  l.rootCount = topology.rootCount;
  return part;
}

}  // namespace

detail::BlurredPart GpuRuntime::Impl::blurredShutterPart(uint32_t p) const {
  if (p < storedPartCount) {
    const StoredPart& s = storedParts[p];
    detail::BlurredPart part = partView({trees[s.tree], s.keys, s.keyNodes.data(), s.keyRootBoxes.data(),
                                         s.keyPositions.data(), s.keyFractions.data(), s.blurNodes.data(),
                                         s.blurTriangles.data()},
                                        *this);
    part.start = s.start;
    return part;
  }
  detail::BlurredPart last = partView({tree(), shutterKeys, keyNodes.data(), keyRootBoxes.data(), keyPositions.data(),
                                       keyFractions.data(), blurNodes.data(), blurTriangles.data()},
                                      *this);
  last.start = shutterKeyTimes.empty() ? 0.0f : shutterKeyTimes.front();
  return last;
}

MotionBvhView GpuRuntime::Impl::motionView() const { return blurredShutterPart(storedPartCount).view; }

detail::BlurredLayout GpuRuntime::Impl::blurredLayout() const { return blurredShutterPart(storedPartCount).layout; }

detail::BlurredShutter GpuRuntime::Impl::blurredShutter() const {
  detail::BlurredShutter s;
  s.first = blurredShutterPart(0);
  if (storedPartCount > 0) {
    s.later = laterParts.data();
    s.laterCount = storedPartCount;
  }
  return s;
}

GpuRuntime::BlurredLayoutCopy GpuRuntime::downloadBlurredLayout() const {
  const Impl& m = *impl_;
  m.requireKey(0);
  BlurredLayoutCopy copy;
  copy.keys = m.shutterKeys;
  copy.nodes = m.blurNodes.download(m.stream, std::size_t(copy.keys - 1) * m.tree().topology.interiorCount);
  const std::vector<detail::KeyTriangle> records =
      m.blurTriangles.download(m.stream, std::size_t(copy.keys) * m.triangles);
  copy.triangles.resize(records.size() * 12);
  std::memcpy(copy.triangles.data(), records.data(), copy.triangles.size() * sizeof(float));
  return copy;
}

GpuRuntime::FrameBytes GpuRuntime::frameBytes() const {
  const Impl& m = *impl_;
  const FlatBvh& topology = m.tree().topology;
  const std::size_t nodes = std::size_t(topology.interiorCount) * sizeof(GpuBvhNode);
  const std::size_t positions = std::size_t(m.vertices) * 3 * sizeof(float);
  FrameBytes b;
  b.instant = nodes + sizeof(detail::RootInfo) + positions + std::size_t(m.triangles) * sizeof(WoopTriangle);
  // The key arrays and the blurred layout built from them, of every part.
  const auto partBytes = [&](std::size_t keys, const FlatBvh& tree) {
    const std::size_t interior = tree.interiorCount;
    return keys * (interior * sizeof(GpuBvhNode) + sizeof(Aabb) + positions + sizeof(float)) +
           (keys - 1) * interior * sizeof(motion::BlurredNodeSegment) +
           keys * std::size_t(m.triangles) * sizeof(detail::KeyTriangle);
  };
  if (m.shutterKeys >= 2) {
    b.blurred = partBytes(m.shutterKeys, topology);
    for (uint32_t p = 0; p < m.storedPartCount; ++p)
      b.blurred += partBytes(m.storedParts[p].keys, m.trees[m.storedParts[p].tree].topology) + sizeof(detail::BlurredPart);
  }
  return b;
}

namespace {

template <typename Result>
std::vector<Result> traceBlurred(GpuRuntime::Impl& m, std::span<const Ray> rays, std::span<const float> times,
                                 RayPassStats* stats) {
  const detail::BlurredShutter frame = m.blurredShutter();
  return traceHostRays<Result>(
      m, rays, stats,
      [&](uint32_t count) {
        m.rayTimes.reserve(count);
        m.rayTimes.upload(times, m.stream);
      },
      [&](uint32_t count, Hit* hits, uint8_t* occluded) {
        detail::launchBlurredTrace(frame, m.rays.data(), m.rayTimes.data(), count, hits, occluded, m.stream);
      });
}

void checkTimeCount(std::span<const Ray> rays, std::span<const float> times) {
  if (rays.size() != times.size())
    throw tsah::ConfigError("GPU runtime: " + std::to_string(times.size()) + " ray times for " +
                            std::to_string(rays.size()) + " rays");
}

}  // namespace

std::vector<Hit> GpuRuntime::closestHits(std::span<const Ray> rays, std::span<const float> times,
                                         RayPassStats* stats) {
  checkTimeCount(rays, times);
  if (!blurred()) return closestHits(rays, stats);
  return traceBlurred<Hit>(*impl_, rays, times, stats);
}

std::vector<uint8_t> GpuRuntime::anyHits(std::span<const Ray> rays, std::span<const float> times,
                                         RayPassStats* stats) {
  checkTimeCount(rays, times);
  if (!blurred()) return anyHits(rays, stats);
  return traceBlurred<uint8_t>(*impl_, rays, times, stats);
}

}  // namespace tsah::cuda
