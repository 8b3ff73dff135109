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
  // One tree for the whole shutter: the one of its middle (the frame's time for a centered shutter).
  m.current = treeIndexAt(m.ranges, 0.5 * (open + close));
  const std::vector<double> times = motion::shutterKeys(m.times, open, close);
  if (times.size() == 1) return m.refitAt(times[0]);
  const std::vector<float> fractions = motion::keyFractions(times);
  m.requireBinaryLayout();
  return m.refitAnimationKeys(times, fractions);
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
uint32_t GpuRuntime::shutterKeyCount() const { return impl_->shutterKeys; }

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

MotionBvhView GpuRuntime::Impl::motionView() const {
  const FlatBvh& topology = tree().topology;
  MotionBvhView view;
  view.keyNodes = keyNodes.data();
  view.keyRootBoxes = keyRootBoxes.data();
  view.keyPositions = keyPositions.data();
  view.keyTimes = keyFractions.data();
  view.keyCount = shutterKeys;
  view.nodeCount = topology.interiorCount;
  view.vertexCount = vertices;
  view.triIndex = tree().triIndex.data();
  view.indices = indices.data();
  view.rootRef = topology.rootRef;
  view.rootCount = topology.rootCount;
  return view;
}

detail::BlurredLayout GpuRuntime::Impl::blurredLayout() const {
  const FlatBvh& topology = tree().topology;
  detail::BlurredLayout l;
  l.nodes = blurNodes.data();
  l.triangles = blurTriangles.data();
  l.keyRootBoxes = keyRootBoxes.data();
  l.keyTimes = keyFractions.data();
  l.triIndex = tree().triIndex.data();
  l.keyCount = shutterKeys;
  l.rootRef = topology.rootRef;
  l.rootCount = topology.rootCount;
  return l;
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
  const std::size_t keys = m.shutterKeys;
  // The key arrays and the blurred layout built from them.
  if (keys >= 2)
    b.blurred = keys * (nodes + sizeof(Aabb) + positions + sizeof(float)) +
                (keys - 1) * std::size_t(topology.interiorCount) * sizeof(motion::BlurredNodeSegment) +
                keys * std::size_t(m.triangles) * sizeof(detail::KeyTriangle);
  return b;
}

namespace {

template <typename Result>
std::vector<Result> traceBlurred(GpuRuntime::Impl& m, std::span<const Ray> rays, std::span<const float> times,
                                 RayPassStats* stats) {
  const detail::BlurredLayout frame = m.blurredLayout();
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
