// CpuRuntime's motion blur (docs/motion-blur.md): the current tree refitted at every key of a
// shutter by the instant refit, one node set, root box and position set kept per key.
#include <algorithm>
#include <cmath>
#include <string>

#include "tsah/base/error.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace tsah {

void CpuRuntime::clearShutter() {
  keyTimes_.clear();
  keyNodes_.clear();
  keyRootBoxes_.clear();
  keyPositions_.clear();
  keyWide4_.clear();
  keyWide8_.clear();
  motionView_ = MotionBvhView{};
}

template <uint32_t N>
void CpuRuntime::keepWideKey(const WideTree<N>& tree, std::vector<WideSoaNode<N>>& keyNodes, std::size_t key) {
  const auto nodes = tree.nodes();
  keyNodes.resize((key + 1) * nodes.size());
  std::copy(nodes.begin(), nodes.end(), keyNodes.begin() + std::ptrdiff_t(key * nodes.size()));
}

// The view of key s with the lerped root box, and key s + 1 with f, for one ray's time.
template <uint32_t N>
std::pair<WideView<N>, WideMotionFrame<N>> CpuRuntime::motionFrame(const WideView<N>& view,
                                                                   const std::vector<WideSoaNode<N>>& keyNodes,
                                                                   float time) const {
  const motion::Segment seg = motion::segmentAt(keyTimes_.data(), int(keyTimes_.size()), time);
  const std::size_t k0 = std::size_t(seg.index), k1 = k0 + 1;
  const std::size_t nodes = keyNodes.size() / keyTimes_.size(), floats = std::size_t(vertexCount_) * 3;
  WideView<N> v = view;
  v.nodes = keyNodes.data() + k0 * nodes;
  v.positions = keyPositions_.data() + k0 * floats;
  v.rootBox = motion::lerpBox(keyRootBoxes_[k0], keyRootBoxes_[k1], seg.f);
  WideMotionFrame<N> m;
  m.nodes1 = keyNodes.data() + k1 * nodes;
  m.positions1 = keyPositions_.data() + k1 * floats;
  m.f = seg.f;
  return {v, m};
}

void CpuRuntime::updateShutter(std::span<const float> keyTimes,
                               std::span<const std::span<const float>> keyPositions) {
  motion::checkKeyTimes(keyTimes, keyPositions.size(), "runtime: ");
  if (keyTimes.size() == 1) {
    update(keyPositions[0]);
    return;
  }
  const std::size_t keys = keyTimes.size();
  const std::size_t floats = std::size_t(vertexCount_) * 3;
  for (std::size_t k = 0; k < keys; ++k)
    if (keyPositions[k].size() != floats)
      throw tsah::DataError("runtime: key " + std::to_string(k) + " has " + std::to_string(keyPositions[k].size()) +
                            " coordinates, expected " + std::to_string(floats));
  const std::size_t nodes = wide4_   ? wide4_->nodes().size() * sizeof(WideSoaNode<4>)
                            : wide8_ ? wide8_->nodes().size() * sizeof(WideSoaNode<8>)
                                     : tree_.interiorCount * sizeof(GpuBvhNode);
  checkFitsInMemory(keys * (nodes + floats * sizeof(float) + sizeof(Aabb)), "runtime",
                    "a shutter of " + std::to_string(keys) + " keys");
  clearShutter();
  // The instant refit at each key; the layout traced keeps its node set per key (the wide layouts
  // do not refit the binary tree).
  const bool wide = wide4_ || wide8_;
  const std::size_t nodeCount = wide ? 0 : tree_.interiorCount;
  std::vector<GpuBvhNode> nodeSets(keys * nodeCount);
  std::vector<Aabb> rootBoxes(keys);
  std::vector<float> positionSets(keys * floats);
  for (std::size_t k = 0; k < keys; ++k) {
    setPositions(keyPositions[k]);
    refitAndWoop();
    if (wide4_) keepWideKey(*wide4_, keyWide4_, k);
    if (wide8_) keepWideKey(*wide8_, keyWide8_, k);
    if (!wide) std::copy_n(tree_.nodes.begin(), nodeCount, nodeSets.begin() + std::ptrdiff_t(k * nodeCount));
    rootBoxes[k] = bounds();
    std::copy(positions_.begin(), positions_.end(), positionSets.begin() + std::ptrdiff_t(k * floats));
  }
  keyTimes_.assign(keyTimes.begin(), keyTimes.end());
  keyNodes_ = std::move(nodeSets);
  keyRootBoxes_ = std::move(rootBoxes);
  keyPositions_ = std::move(positionSets);
  // The key positions, times and triangles in every layout (the renderer's blurred surfaces read
  // them); the binary key nodes in bvh2 only.
  MotionBvhView& v = motionView_;
  v.keyNodes = wide ? nullptr : keyNodes_.data();
  v.keyRootBoxes = keyRootBoxes_.data();
  v.keyPositions = keyPositions_.data();
  v.keyTimes = keyTimes_.data();
  v.keyCount = uint32_t(keys);
  v.nodeCount = uint32_t(nodeCount);
  v.vertexCount = vertexCount_;
  v.triIndex = tree_.triIndex.data();
  v.indices = indices_.data();
  v.rootRef = tree_.rootRef;
  v.rootCount = tree_.rootCount;
}

Hit CpuRuntime::closestHit(const Ray& ray, float time) const {
  if (!blurred()) return closestHit(ray);
  if (wide8_) {
    const auto [v, m] = motionFrame(view8_, keyWide8_, time);
    return kernels_->closestMotion8(v, m, ray);
  }
  if (wide4_) {
    const auto [v, m] = motionFrame(view4_, keyWide4_, time);
    return kernels_->closestMotion4(v, m, ray);
  }
  return tsah::closestHit(motionView_, ray, time);
}

bool CpuRuntime::anyHit(const Ray& ray, float time, AnyHitOrder order) const {
  if (!blurred()) return anyHit(ray, order);
  if (wide8_) {
    const auto [v, m] = motionFrame(view8_, keyWide8_, time);
    return kernels_->anyMotion8(v, m, ray, order);
  }
  if (wide4_) {
    const auto [v, m] = motionFrame(view4_, keyWide4_, time);
    return kernels_->anyMotion4(v, m, ray, order);
  }
  return tsah::anyHit(motionView_, ray, time);
}

}  // namespace tsah
