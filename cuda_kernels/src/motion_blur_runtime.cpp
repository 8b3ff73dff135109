// GpuRuntime's motion blur from host positions: the current tree refitted at every key of a shutter,
// one copy of the traced tree's nodes, root and positions per key (docs/cuda-runtime.md).
#include <cmath>
#include <string>

#include "tsah/base/error.hpp"
#include "cwbvh_kernels.hpp"
#include "runtime_impl.hpp"

namespace tsah::cuda {

namespace {

// The key times of the design: one key anywhere in [0, 1], else first 0, last 1, increasing.
void checkKeyTimes(std::span<const float> keyTimes, std::size_t positionSets) {
  const std::string where = "GPU runtime: updateShutter: ";
  if (keyTimes.empty()) throw tsah::ConfigError(where + "no keys");
  if (keyTimes.size() != positionSets)
    throw tsah::ConfigError(where + std::to_string(keyTimes.size()) + " key times for " +
                            std::to_string(positionSets) + " sets of positions");
  for (float k : keyTimes)
    if (!std::isfinite(k) || k < 0.0f || k > 1.0f)
      throw tsah::ConfigError(where + "key time " + std::to_string(k) + " is outside [0, 1]");
  if (keyTimes.size() == 1) return;
  if (keyTimes.front() != 0.0f || keyTimes.back() != 1.0f)
    throw tsah::ConfigError(where + "the first key time must be 0 and the last 1");
  for (std::size_t k = 1; k < keyTimes.size(); ++k)
    if (!(keyTimes[k] > keyTimes[k - 1])) throw tsah::ConfigError(where + "key times must increase");
}

}  // namespace

void GpuRuntime::Impl::requireKey(uint32_t key) const {
  if (shutterKeys == 0) throw tsah::ConfigError("GPU runtime: the frame is not blurred (no updateShutter)");
  if (key >= shutterKeys)
    throw tsah::ConfigError("GPU runtime: key " + std::to_string(key) + " of a shutter with " +
                            std::to_string(shutterKeys) + " keys");
}

UpdateTimings GpuRuntime::updateShutter(std::span<const float> keyTimes,
                                        std::span<const std::span<const float>> keyPositions) {
  Impl& m = *impl_;
  checkKeyTimes(keyTimes, keyPositions.size());
  if (keyTimes.size() == 1) return update(keyPositions[0]);
  if (m.config.layout != Layout::Bvh2)
    throw tsah::ConfigError("GPU runtime: motion blur traces the binary layout on the GPU (layout bvh2, not " +
                            std::string(name(m.config.layout)) + ")");
  for (std::span<const float> p : keyPositions)  // before anything is refitted
    if (p.size() != std::size_t(m.vertices) * 3)
      throw tsah::DataError("GPU runtime: updateShutter got " + std::to_string(p.size()) +
                            " coordinates for a key, expected " + std::to_string(std::size_t(m.vertices) * 3));
  const auto keys = static_cast<uint32_t>(keyTimes.size());
  Impl::DeviceTree& t = m.tree();
  const std::size_t interior = t.topology.interiorCount, coords = std::size_t(m.vertices) * 3;
  m.keyNodes.reserve(std::size_t(keys) * interior);
  m.keyRoots.reserve(keys);
  m.keyPositions.reserve(std::size_t(keys) * coords);
  UpdateTimings total;
  for (uint32_t k = 0; k < keys; ++k) {
    // Each key is the update from host positions (bit-identical to CpuRuntime::update), kept.
    const UpdateTimings one = update(keyPositions[k]);
    total.interpolateMs += one.interpolateMs;
    total.refitMs += one.refitMs;
    total.woopMs += one.woopMs;
    if (interior)
      CUDA_CHECK(cudaMemcpyAsync(m.keyNodes.data() + k * interior, t.nodes.data(), interior * sizeof(GpuBvhNode),
                                 cudaMemcpyDeviceToDevice, m.stream));
    CUDA_CHECK(cudaMemcpyAsync(m.keyRoots.data() + k, t.root.data(), sizeof(detail::RootInfo),
                               cudaMemcpyDeviceToDevice, m.stream));
    CUDA_CHECK(cudaMemcpyAsync(m.keyPositions.data() + k * coords, m.positions.data(), coords * sizeof(float),
                               cudaMemcpyDeviceToDevice, m.stream));
  }
  CUDA_CHECK(cudaStreamSynchronize(m.stream));
  m.shutterKeys = keys;
  m.shutterKeyTimes.assign(keyTimes.begin(), keyTimes.end());
  return total;
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
  detail::RootInfo root;
  CUDA_CHECK(cudaMemcpyAsync(&root, m.keyRoots.data() + key, sizeof root, cudaMemcpyDeviceToHost, m.stream));
  CUDA_CHECK(cudaStreamSynchronize(m.stream));
  flat.rootBoxes = {root.box};
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

}  // namespace tsah::cuda
