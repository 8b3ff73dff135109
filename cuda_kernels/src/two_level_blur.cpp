// The GPU two-level runtime's motion blur (two_level_blur.hpp): the shutter's keys and what moves
// (tsah::shutterMotion, the CPU's), the moving poses' BLAS at every key, the instances' key boxes,
// the TLAS at every key, and the traces at each ray's time.
#include <cuda_runtime_api.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "kernels.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "two_level_blur.hpp"
#include "two_level_device_data.hpp"

namespace tsah::cuda {

namespace detail {

namespace {

// dst[0, count * one.size()) = `count` copies of `one` (device memory), by copies on the device that
// double the filled part: a blurred frame's items start from one state without a host copy of each.
template <typename T>
void broadcast(const DeviceBuffer<T>& one, T* dst, std::size_t count, cudaStream_t stream) {
  const std::size_t n = one.size();
  if (count == 0 || n == 0) return;
  CUDA_CHECK(cudaMemcpyAsync(dst, one.data(), n * sizeof(T), cudaMemcpyDeviceToDevice, stream));
  for (std::size_t filled = 1; filled < count;) {
    const std::size_t more = std::min(filled, count - filled);
    CUDA_CHECK(cudaMemcpyAsync(dst + filled * n, dst, more * n * sizeof(T), cudaMemcpyDeviceToDevice, stream));
    filled += more;
  }
}

template <typename T>
void uploadGrown(DeviceBuffer<T>& buffer, const std::vector<T>& host, cudaStream_t stream) {
  buffer.reserve(host.size());
  buffer.upload(host, stream);
}

// The root boxes of `count` RootInfo records into a dense box array (RootInfo starts with its box).
void copyRootBoxes(const RootInfo* roots, std::size_t count, Aabb* boxes, cudaStream_t stream) {
  static_assert(offsetof(RootInfo, box) == 0);
  if (count == 0) return;
  CUDA_CHECK(cudaMemcpy2DAsync(boxes, sizeof(Aabb), roots, sizeof(RootInfo), sizeof(Aabb), count,
                               cudaMemcpyDeviceToDevice, stream));
}

RootInfo rootInfoOf(const FlatBvh& tree) {
  RootInfo root;
  root.ref = tree.rootRef;
  root.count = tree.rootCount;
  return root;
}

}  // namespace

TwoLevelBlur::TwoLevelBlur() { events_.create(2); }

void TwoLevelBlur::buildPoses(const TwoLevelBlurAccess& access, const ShutterMotion& motion, std::size_t keyCount,
                              std::vector<BlurredLayout>& layouts, std::vector<BlurredPosePositions>& positions,
                              std::vector<uint32_t>& poseLayout,
                              std::vector<Aabb>& poseUnion) {
  const TwoLevelScene& scene = *access.scene;
  const cudaStream_t stream = access.stream;
  const auto keys = uint32_t(keyCount);
  std::vector<std::vector<uint32_t>> movingOf(scene.blases.size());  // per BLAS: its moving poses
  for (uint32_t p = 0; p < scene.poses.size(); ++p)
    if (motion.movingPoses[p]) movingOf[scene.poses[p].blas].push_back(p);
  poseKeys_.resize(scene.blases.size());
  for (uint32_t b = 0; b < scene.blases.size(); ++b) {
    const std::vector<uint32_t>& moving = movingOf[b];
    if (moving.empty()) continue;
    const BlurSource& source = access.sources[b];
    const FlatBvh& topology = *source.topology;
    const anim::Animation& a = *scene.scene.sources[scene.blases[b].source];
    const auto members = uint32_t(moving.size());
    const uint32_t items = members * keys, interior = topology.interiorCount, slots = topology.triangleCount();
    // Every item starts as the BLAS's start state: the static vertices at rest (the interpolation
    // rewrites the moving ones) and the nodes' child references (the refit rewrites the boxes),
    // uploaded once per source.
    PoseKeys& g = poseKeys_[b];
    if (g.startPositions.size() == 0) {
      g.startPositions = DeviceBuffer<float>(std::span<const float>(a.positionsAt(a.startTime())), stream);
      g.startNodes = DeviceBuffer<GpuBvhNode>(std::span<const GpuBvhNode>(topology.nodes), stream);
    }
    const uint64_t stride = g.startPositions.size();
    g.positions.reserve(std::size_t(items) * stride);
    broadcast(g.startPositions, g.positions.data(), items, stream);
    g.nodes.reserve(std::size_t(items) * interior);
    broadcast(g.startNodes, g.nodes.data(), items, stream);
    g.counters.reserve(std::size_t(items) * interior);
    g.counters.fillBytes(0, stream);
    uploadGrown(g.roots, std::vector<RootInfo>(items, rootInfoOf(topology)), stream);
    std::vector<FrameParams> frames(items);
    for (uint32_t j = 0; j < members; ++j)
      for (uint32_t k = 0; k < keys; ++k) {
        const auto [key, alpha] = anim::keyframeBlend(a.times(), motion.poseLocal[moving[j]][k]);
        frames[j * keys + k] = blendFrame(key, alpha, a.movingVertexCount());
      }
    uploadGrown(g.frames, frames, stream);
    launchBatchInterpolate(source.keyframes, source.movingIds, g.frames.data(), g.positions.data(), source.movingCount,
                           items, stride, stream);
    BatchStrides strides;
    strides.positions = stride;
    strides.nodes = interior;
    strides.counters = interior;
    launchBatchRefit(g.nodes.data(), source.nodeParent, source.leaves, source.leafCount, source.slotVertices,
                     g.positions.data(), g.counters.data(), g.roots.data(), items, strides, stream);
    g.keyRootBoxes.reserve(items);
    copyRootBoxes(g.roots.data(), items, g.keyRootBoxes.data(), stream);
    g.layoutNodes.reserve(std::size_t(members) * (keys - 1) * interior);
    g.layoutTriangles.reserve(std::size_t(members) * keys * slots);
    for (uint32_t j = 0; j < members; ++j) {
      BlurredLayoutSources from;
      from.keyNodes = g.nodes.data() + std::size_t(j) * keys * interior;
      from.nodeCount = interior;
      from.keyPositions = g.positions.data() + std::size_t(j) * keys * stride;
      from.keyStride = stride;
      from.slotVertices = source.slotVertices;
      from.slots = slots;
      from.keyCount = keys;
      motion::BlurredNodeSegment* nodes = g.layoutNodes.data() + std::size_t(j) * (keys - 1) * interior;
      KeyTriangle* triangles = g.layoutTriangles.data() + std::size_t(j) * keys * slots;
      launchBuildBlurredLayout(from, nodes, triangles, stream);
      BlurredLayout layout;
      layout.nodes = nodes;
      layout.triangles = triangles;
      layout.keyRootBoxes = g.keyRootBoxes.data() + std::size_t(j) * keys;
      layout.keyTimes = deviceKeyTimes_.data();
      layout.triIndex = source.triIndex;
      layout.keyCount = keys;
      layout.rootRef = topology.rootRef;
      layout.rootCount = topology.rootCount;
      poseLayout[moving[j]] = uint32_t(layouts.size());
      layouts.push_back(layout);
      positions.push_back({from.keyPositions, from.keyStride});
    }
  }
  // Each moving pose's root boxes over the keys, united (waits for the refits).
  for (uint32_t b = 0; b < scene.blases.size(); ++b) {
    if (movingOf[b].empty()) continue;
    const std::vector<Aabb> roots = poseKeys_[b].keyRootBoxes.download(stream, movingOf[b].size() * keys);
    for (std::size_t j = 0; j < movingOf[b].size(); ++j) {
      Aabb u;
      for (uint32_t k = 0; k < keys; ++k) u.extend(roots[j * keys + k]);
      poseUnion[movingOf[b][j]] = u;
    }
  }
}

void TwoLevelBlur::build(const TwoLevelBlurAccess& access, std::span<const double> keys, const ShutterMotion& motion) {
  keyTimes_.clear();
  const TwoLevelScene& scene = *access.scene;
  const cudaStream_t stream = access.stream;
  const std::size_t keyCount = keys.size();
  const uint32_t count = scene.instanceCount();
  const std::vector<float> fractions = motion::keyFractions(keys);
  uploadGrown(deviceKeyTimes_, fractions, stream);

  // The moving poses' BLAS at every key; every other instance's BLAS is its instant view.
  std::vector<BlurredLayout> layouts;
  std::vector<uint32_t> poseLayout(scene.poses.size(), kInvalidIndex);
  std::vector<Aabb> poseUnion(scene.poses.size());
  std::vector<BlurredPosePositions> positions;
  buildPoses(access, motion, keyCount, layouts, positions, poseLayout, poseUnion);

  // U, the union of an instance's BLAS root boxes over the keys (a still BLAS: its root box), and
  // its box at each key (instanceKeyBox: the CPU's, so the TLAS boxes are the CPU's).
  rootBoxes_.reserve(count);
  launchInstanceRootBoxes(access.instances, access.views, count, rootBoxes_.data(), stream);
  std::vector<Aabb> local = rootBoxes_.download(stream, count);
  std::vector<BlurredInstance> instances(count);
  for (uint32_t i = 0; i < count; ++i) {
    instances[i].moving = motion.movingInstances[i];
    const uint32_t p = scene.instancePose[i];
    if (p == kInvalidIndex || poseLayout[p] == kInvalidIndex) continue;
    instances[i].layout = poseLayout[p];
    local[i] = poseUnion[p];
  }
  hostKeyBoxes_.resize(keyCount * count);
  for (std::size_t k = 0; k < keyCount; ++k)
    for (uint32_t i = 0; i < count; ++i)
      hostKeyBoxes_[k * count + i] = instanceKeyBox(local[i], motion.toWorld[k * count + i]);
  uploadGrown(keyBoxes_, hostKeyBoxes_, stream);
  uploadGrown(keyToWorld_, motion.toWorld, stream);
  uploadGrown(instances_, instances, stream);
  uploadGrown(layouts_, layouts, stream);
  uploadGrown(posePositions_, positions, stream);

  // The TLAS refitted at every key from that key's boxes (one node set and root per key).
  const FlatBvh& tlas = *access.tlas;
  const uint32_t interior = tlas.interiorCount;
  uploadGrown(tlasKeyNodes_, repeated(std::span<const GpuBvhNode>(tlas.nodes), keyCount), stream);
  tlasCounters_.reserve(keyCount * interior);
  tlasCounters_.fillBytes(0, stream);
  uploadGrown(tlasKeyRoots_, std::vector<RootInfo>(keyCount, rootInfoOf(tlas)), stream);
  for (std::size_t k = 0; k < keyCount; ++k)
    launchTlasRefit(tlasKeyNodes_.data() + k * interior, access.tlasParent, access.tlasLeaves, access.tlasLeafCount,
                    access.tlasTriIndex, keyBoxes_.data() + k * count, tlasCounters_.data() + k * interior,
                    tlasKeyRoots_.data() + k, stream);
  tlasKeyRootBoxes_.reserve(keyCount);
  copyRootBoxes(tlasKeyRoots_.data(), keyCount, tlasKeyRootBoxes_.data(), stream);
  CUDA_CHECK(cudaStreamSynchronize(stream));

  scene_ = {};
  scene_.keyNodes = tlasKeyNodes_.data();
  scene_.nodeCount = interior;
  scene_.keyRootBoxes = tlasKeyRootBoxes_.data();
  scene_.keyTimes = deviceKeyTimes_.data();
  scene_.keyCount = uint32_t(keyCount);
  scene_.rootRef = tlas.rootRef;
  scene_.rootCount = tlas.rootCount;
  scene_.triIndex = access.tlasTriIndex;
  scene_.instanceCount = count;
  scene_.keyBoxes = keyBoxes_.data();
  scene_.keyToWorld = keyToWorld_.data();
  scene_.blurred = instances_.data();
  scene_.instances = access.instances;
  scene_.views = access.views;
  scene_.compressedBlas = access.compressedBlas;
  scene_.layouts = layouts_.data();
  scene_.posePositions = posePositions_.data();
  stream_ = stream;
  keyTimes_ = fractions;
}

std::span<const Aabb> TwoLevelBlur::keyInstanceBoxes(std::size_t key) const {
  if (key >= keyTimes_.size())
    throw ConfigError("GPU two-level runtime: key " + std::to_string(key) + " of a shutter of " +
                      std::to_string(keyTimes_.size()) + " keys");
  const std::size_t count = scene_.instanceCount;
  return std::span<const Aabb>(hostKeyBoxes_).subspan(key * count, count);
}

template <bool AnyHit, typename Result>
std::vector<Result> TwoLevelBlur::trace(std::span<const Ray> in, std::span<const float> times, RayPassStats* stats) {
  if (!in.empty()) {
    rayTimes_.reserve(times.size());
    rayTimes_.upload(times, stream_);
  }
  return query_.run<AnyHit, Result>(in, events_, stream_, stats,
                                    [&](const Ray* rays, uint32_t count, InstanceHit* hits, uint8_t* occluded) {
                                      launchBlurredTwoLevelTrace(scene_, rays, rayTimes_.data(), count, hits,
                                                                 occluded, stream_);
                                    });
}

}  // namespace detail

namespace {

void checkTimeCount(std::span<const Ray> rays, std::span<const float> times) {
  if (rays.size() != times.size())
    throw ConfigError("GPU two-level runtime: " + std::to_string(times.size()) + " ray times for " +
                      std::to_string(rays.size()) + " rays");
}

}  // namespace

void GpuTwoLevelRuntime::updateShutter(double openTime, double closeTime) {
  if (!(std::isfinite(openTime) && std::isfinite(closeTime) && openTime <= closeTime))
    throw ConfigError("GPU two-level runtime: a shutter needs finite times with open <= close, got [" +
                      std::to_string(openTime) + ", " + std::to_string(closeTime) + "]");
  const std::vector<double> keys = motion::shutterKeys(scene().frameTimes, openTime, closeTime);
  if (keys.size() < 2) {
    updateAt(openTime);
    return;
  }
  const ShutterMotion moves = shutterMotion(scene(), keys);
  if (!moves.anyMoves) {  // nothing moves: the instant at the open
    updateAt(openTime);
    return;
  }
  // The instant state at the close: what still instances and still poses trace, and what tracing
  // without times sees (as the CPU runtime); it ends any earlier blurred frame.
  updateAt(closeTime);
  if (!blur_) blur_ = std::make_unique<detail::TwoLevelBlur>();
  blur_->build(blurAccess(), keys, moves);
}

bool GpuTwoLevelRuntime::blurred() const { return blur_ && blur_->blurred(); }

std::span<const float> GpuTwoLevelRuntime::keyTimes() const {
  return blurred() ? blur_->keyTimes() : std::span<const float>();
}

std::vector<Aabb> GpuTwoLevelRuntime::keyInstanceBoxes(std::size_t key) const {
  if (!blurred()) throw ConfigError("GPU two-level runtime: the frame is not blurred (no updateShutter)");
  const std::span<const Aabb> boxes = blur_->keyInstanceBoxes(key);
  return {boxes.begin(), boxes.end()};
}

std::vector<TwoLevelHit> GpuTwoLevelRuntime::closestHits(std::span<const Ray> rays, std::span<const float> times,
                                                         RayPassStats* stats) {
  checkTimeCount(rays, times);
  if (!blurred()) return closestHits(rays, stats);
  return blur_->trace<false, TwoLevelHit>(rays, times, stats);
}

std::vector<uint8_t> GpuTwoLevelRuntime::anyHits(std::span<const Ray> rays, std::span<const float> times,
                                                 RayPassStats* stats) {
  checkTimeCount(rays, times);
  if (!blurred()) return anyHits(rays, stats);
  return blur_->trace<true, uint8_t>(rays, times, stats);
}

}  // namespace tsah::cuda
