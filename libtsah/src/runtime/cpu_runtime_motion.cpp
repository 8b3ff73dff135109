// CpuRuntime's motion blur (docs/motion-blur.md): the current tree refitted at every key of a
// shutter by the instant refit, one node set, root box and position set kept per key.
#include <algorithm>
#include <cmath>
#include <string>

#include "tsah/base/error.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace tsah {

void CpuRuntime::clearShutter() {
  keyTimes_.clear();
  keyNodes_.clear();
  keyRootBoxes_.clear();
  keyPositions_.clear();
  motionView_ = MotionBvhView{};
}

void CpuRuntime::updateShutter(std::span<const float> keyTimes,
                               std::span<const std::span<const float>> keyPositions) {
  motion::checkKeyTimes(keyTimes, keyPositions.size(), "runtime: ");
  if (keyTimes.size() == 1) {
    update(keyPositions[0]);
    return;
  }
  if (info_.layout != Layout::Bvh2)
    throw tsah::ConfigError("runtime: motion blur traces the bvh2 layout only so far, not " +
                            std::string(name(info_.layout)));
  const std::size_t keys = keyTimes.size();
  const std::size_t floats = std::size_t(vertexCount_) * 3;
  for (std::size_t k = 0; k < keys; ++k)
    if (keyPositions[k].size() != floats)
      throw tsah::DataError("runtime: key " + std::to_string(k) + " has " + std::to_string(keyPositions[k].size()) +
                            " coordinates, expected " + std::to_string(floats));
  const std::size_t nodes = tree_.interiorCount;
  checkFitsInMemory(keys * (nodes * sizeof(GpuBvhNode) + floats * sizeof(float) + sizeof(Aabb)), "runtime",
                    "a shutter of " + std::to_string(keys) + " keys");
  clearShutter();
  std::vector<GpuBvhNode> nodeSets(keys * nodes);
  std::vector<Aabb> rootBoxes(keys);
  std::vector<float> positionSets(keys * floats);
  for (std::size_t k = 0; k < keys; ++k) {  // the instant refit at each key
    setPositions(keyPositions[k]);
    refitAndWoop();
    std::copy_n(tree_.nodes.begin(), nodes, nodeSets.begin() + std::ptrdiff_t(k * nodes));
    rootBoxes[k] = tree_.rootBoxes[0];
    std::copy(positions_.begin(), positions_.end(), positionSets.begin() + std::ptrdiff_t(k * floats));
  }
  keyTimes_.assign(keyTimes.begin(), keyTimes.end());
  keyNodes_ = std::move(nodeSets);
  keyRootBoxes_ = std::move(rootBoxes);
  keyPositions_ = std::move(positionSets);
  MotionBvhView& v = motionView_;
  v.keyNodes = keyNodes_.data();
  v.keyRootBoxes = keyRootBoxes_.data();
  v.keyPositions = keyPositions_.data();
  v.keyTimes = keyTimes_.data();
  v.keyCount = uint32_t(keys);
  v.nodeCount = uint32_t(nodes);
  v.vertexCount = vertexCount_;
  v.triIndex = tree_.triIndex.data();
  v.indices = indices_.data();
  v.rootRef = tree_.rootRef;
  v.rootCount = tree_.rootCount;
}

Hit CpuRuntime::closestHit(const Ray& ray, float time) const {
  if (!blurred()) return closestHit(ray);
  return tsah::closestHit(motionView_, ray, time);
}

bool CpuRuntime::anyHit(const Ray& ray, float time, AnyHitOrder order) const {
  if (!blurred()) return anyHit(ray, order);
  return tsah::anyHit(motionView_, ray, time);
}

}  // namespace tsah
