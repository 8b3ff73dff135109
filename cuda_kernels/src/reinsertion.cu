// The GPU optimizer: ReinsertionRounds (tsah/reinsertion_rounds.hpp) over a CUDA backend. Every
// phase is one launch of forEachKernel with the phase object; compaction and sorting are CUB's.
// Compiled without fused multiply-adds, so every phase rounds as the host emulation does.
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_select.cuh>
#include <thrust/iterator/counting_iterator.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <string>
#include <typeinfo>
#include <utility>
#include <vector>

#include <cxxabi.h>

#include <cstdlib>

#include "launch.hpp"
#include "tsah/optimize/detail/reinsertion_rounds.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/gpu_optimizer.hpp"

namespace tsah::cuda {

namespace {

template <class Phase>
__global__ void forEachKernel(uint32_t count, Phase phase) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < count) phase(i);
}

// Persistent threads: each thread takes the next index as soon as it is done with one, so a warp's
// lanes do not wait for its slowest search before new work starts (the results do not depend on
// which thread runs an index).
template <class Phase>
__global__ void forEachDynamicKernel(uint32_t count, unsigned* next, Phase phase) {
  for (;;) {
    const uint32_t i = atomicAdd(next, 1u);
    if (i >= count) return;
    phase(i);
  }
}

// A phase's name from its type ("tsah::reinsertion::SearchCandidates<false>" -> without the namespace).
std::string phaseName(const char* mangled) {
  int status = 0;
  char* demangled = abi::__cxa_demangle(mangled, nullptr, nullptr, &status);
  std::string name = status == 0 && demangled ? demangled : mangled;
  std::free(demangled);
  const std::string prefix = "tsah::reinsertion::";
  return name.rfind(prefix, 0) == 0 ? name.substr(prefix.size()) : name;
}

// allocated (CountedArrays): bytes of the optimizer's buffers (CUB's included).
class CudaBackend : public reinsertion::CountedArrays<DeviceBuffer> {
 public:
  template <class T>
  using Array = DeviceBuffer<T>;

  // profile: every phase, compaction and sort waits for the device and is timed (slower).
  explicit CudaBackend(bool profile = false, GpuSearchKernel search = {})
      : specializedSearch(search.specializedFrames), count_(1), next_(1), dynamicFetch_(search.dynamicFetch),
        profile_(profile) {}
  CudaBackend(CudaBackend&&) noexcept = default;

  std::vector<GpuPhaseTime> phaseTimes() const {
    std::vector<GpuPhaseTime> out;
    for (const auto& [name, t] : times_) out.push_back(t);
    return out;
  }

  bool specializedSearch = false;
  template <class T>
  void upload(Array<T>& array, const T* host, std::size_t count) {
    if (count) CUDA_CHECK(cudaMemcpy(array.data(), host, count * sizeof(T), cudaMemcpyHostToDevice));
  }
  template <class T>
  void download(const Array<T>& array, T* host, std::size_t count, std::size_t offset) {
    if (count) CUDA_CHECK(cudaMemcpy(host, array.data() + offset, count * sizeof(T), cudaMemcpyDeviceToHost));
  }
  void zero(void* pointer, std::size_t bytes) {
    if (bytes) CUDA_CHECK(cudaMemsetAsync(pointer, 0, bytes));
  }
  template <class Phase>
  void forEach(uint32_t count, const Phase& phase) {
    if (count == 0) return;
    const auto start = profileStart();
    constexpr unsigned kBlock = 128;
    forEachKernel<<<detail::gridFor(count, kBlock), kBlock>>>(count, phase);
    CUDA_CHECK_LAUNCH("reinsertion phase");
    if (profile_) profileEnd(phaseName(typeid(Phase).name()), start);
  }
  // The search: forEach, or persistent threads fetching indices (GpuSearchKernel::dynamicFetch).
  template <class Phase>
  void forEachBalanced(uint32_t count, const Phase& phase) {
    if (!dynamicFetch_) return forEach(count, phase);
    if (count == 0) return;
    const auto start = profileStart();
    constexpr unsigned kBlock = 128;
    int device = 0, multiprocessors = 0, blocksPerSm = 0;
    CUDA_CHECK(cudaGetDevice(&device));
    CUDA_CHECK(cudaDeviceGetAttribute(&multiprocessors, cudaDevAttrMultiProcessorCount, device));
    CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocksPerSm, forEachDynamicKernel<Phase>, kBlock, 0));
    const std::size_t blocks = std::min<std::size_t>(std::size_t(std::max(1, blocksPerSm)) * multiprocessors,
                                                     (count + kBlock - 1) / kBlock);
    next_.fillBytes(0);
    forEachDynamicKernel<<<unsigned(blocks), kBlock>>>(count, next_.data(), phase);
    CUDA_CHECK_LAUNCH("reinsertion phase (persistent threads)");
    if (profile_) profileEnd(phaseName(typeid(Phase).name()) + " (dynamic)", start);
  }
  uint32_t selectFlagged(const uint8_t* flags, uint32_t count, uint32_t* out) {
    if (count == 0) return 0;
    const auto start = profileStart();
    const thrust::counting_iterator<uint32_t> indices(0);
    std::size_t bytes = 0;
    CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, bytes, indices, flags, out, count_.data(), count));
    reserveTemp(bytes);
    bytes = temp_.size();
    CUDA_CHECK(cub::DeviceSelect::Flagged(temp_.data(), bytes, indices, flags, out, count_.data(), count));
    uint32_t selected = 0;
    download(count_, &selected, 1, 0);
    if (profile_) profileEnd("select (CUB)", start);
    return selected;
  }
  void sortDescending(unsigned long long* keys, uint32_t* values, uint32_t count) {
    if (count < 2) return;
    const auto start = profileStart();
    reserve(keysAlt_, count);
    reserve(valuesAlt_, count);
    cub::DoubleBuffer<unsigned long long> k(keys, keysAlt_.data());
    cub::DoubleBuffer<uint32_t> v(values, valuesAlt_.data());
    std::size_t bytes = 0;
    CUDA_CHECK(cub::DeviceRadixSort::SortPairsDescending(nullptr, bytes, k, v, count));
    reserveTemp(bytes);
    bytes = temp_.size();
    CUDA_CHECK(cub::DeviceRadixSort::SortPairsDescending(temp_.data(), bytes, k, v, count));
    if (k.Current() != keys) {
      CUDA_CHECK(cudaMemcpyAsync(keys, k.Current(), count * sizeof(unsigned long long), cudaMemcpyDeviceToDevice));
      CUDA_CHECK(cudaMemcpyAsync(values, v.Current(), count * sizeof(uint32_t), cudaMemcpyDeviceToDevice));
    }
    if (profile_) profileEnd("sort (CUB)", start);
  }

 private:
  // CUB's scratch (never empty: a null scratch pointer would make CUB only report its size).
  void reserveTemp(std::size_t bytes) { reserve(temp_, bytes > 0 ? bytes : 1); }

  using Clock = std::chrono::steady_clock;
  Clock::time_point profileStart() {
    if (profile_) CUDA_CHECK(cudaDeviceSynchronize());
    return Clock::now();
  }
  void profileEnd(const std::string& name, Clock::time_point start) {
    CUDA_CHECK(cudaDeviceSynchronize());
    GpuPhaseTime& t = times_[name];
    t.phase = name;
    t.seconds += std::chrono::duration<double>(Clock::now() - start).count();
    ++t.launches;
  }

  DeviceBuffer<uint32_t> count_;
  DeviceBuffer<unsigned> next_;  // the persistent threads' next index
  bool dynamicFetch_ = false;
  bool profile_ = false;
  std::map<std::string, GpuPhaseTime> times_;
  DeviceBuffer<uint8_t> temp_;
  DeviceBuffer<unsigned long long> keysAlt_;
  DeviceBuffer<uint32_t> valuesAlt_;
};

}  // namespace

std::unique_ptr<RoundSession> makeGpuReinsertionSession(Bvh bvh, const PrimitiveBoxes& prims,
                                                        const ParallelReinsertionOptimizer::Config& config,
                                                        const ParallelReinsertionOptimizer::Parallel& parallel) {
  if (!deviceAvailable()) throw CudaError(cudaErrorNoDevice, "--device cuda: no CUDA device is available");
  return std::make_unique<reinsertion::BackendSession<CudaBackend>>(CudaBackend(false, kDefaultSearchKernel),
                                                                    std::move(bvh), prims, config, parallel);
}

InsertionOptimizer::Result optimizeOnGpu(Bvh bvh, const PrimitiveBoxes& prims,
                                         const ParallelReinsertionOptimizer::Config& config,
                                         const ParallelReinsertionOptimizer::Parallel& parallel,
                                         const LeafCollapser* collapse) {
  // The clock starts once the CUDA context exists: creating it (once per process) is not the
  // optimizer's work.
  if (deviceAvailable()) CUDA_CHECK(cudaFree(nullptr));
  const auto start = std::chrono::steady_clock::now();
  const std::unique_ptr<RoundSession> session = makeGpuReinsertionSession(std::move(bvh), prims, config, parallel);
  return runReinsertionRounds(*session, config, collapse, start);
}

InsertionOptimizer::Result profileOnGpu(Bvh bvh, const PrimitiveBoxes& prims,
                                        const ParallelReinsertionOptimizer::Config& config,
                                        const ParallelReinsertionOptimizer::Parallel& parallel,
                                        std::vector<GpuPhaseTime>& times, std::size_t& deviceBytes,
                                        GpuSearchKernel search) {
  if (!deviceAvailable()) throw CudaError(cudaErrorNoDevice, "--device cuda: no CUDA device is available");
  CUDA_CHECK(cudaFree(nullptr));  // the context first, as in optimizeOnGpu
  const auto start = std::chrono::steady_clock::now();
  reinsertion::BackendSession<CudaBackend> session(CudaBackend(true, search), std::move(bvh), prims, config,
                                                   parallel);
  InsertionOptimizer::Result result = runReinsertionRounds(session, config, nullptr, start);
  times = session.backend().phaseTimes();
  deviceBytes = session.backend().allocated;
  return result;
}

TreeOptimizerFunction gpuTreeOptimizer() {
  return [](Bvh bvh, const PrimitiveBoxes& prims, const InsertionOptimizer::Config& settings,
            const LeafCollapser* collapse) { return optimizeOnGpu(std::move(bvh), prims, settings, {}, collapse); };
}

}  // namespace tsah::cuda
