// The emulated device session: ReinsertionRounds over a serial host backend (reinsertion_emulation.hpp).
#include "tsah/optimize/detail/reinsertion_emulation.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <numeric>
#include <utility>
#include <vector>

#include "tsah/optimize/detail/reinsertion_rounds.hpp"

namespace tsah {

namespace {

// Arrays are host vectors; every phase is a loop over its thread indices, in order.
template <class T>
using HostArray = std::vector<T>;

// allocated: bytes of the optimizer's own buffers, as the GPU allocates them.
struct SerialBackend : reinsertion::CountedArrays<HostArray> {
  template <class T>
  using Array = HostArray<T>;

  bool specializedSearch = false;  // the same moves either way
  template <class T>
  void upload(Array<T>& array, const T* host, std::size_t count) {
    std::copy_n(host, count, array.data());
  }
  template <class T>
  void download(const Array<T>& array, T* host, std::size_t count, std::size_t offset) {
    std::copy_n(array.data() + offset, count, host);
  }
  void zero(void* pointer, std::size_t bytes) { std::memset(pointer, 0, bytes); }
  template <class Phase>
  void forEach(uint32_t count, const Phase& phase) {
    for (uint32_t i = 0; i < count; ++i) phase(i);
  }
  template <class Phase>
  void forEachBalanced(uint32_t count, const Phase& phase) {
    forEach(count, phase);
  }
  uint32_t selectFlagged(const uint8_t* flags, uint32_t count, uint32_t* out) {
    uint32_t selected = 0;
    for (uint32_t i = 0; i < count; ++i)
      if (flags[i]) out[selected++] = i;
    return selected;
  }
  void sortDescending(unsigned long long* keys, uint32_t* values, uint32_t count) {
    std::vector<uint32_t> order(count);
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return keys[a] > keys[b]; });
    std::vector<unsigned long long> k(count);
    std::vector<uint32_t> v(count);
    for (uint32_t i = 0; i < count; ++i) {
      k[i] = keys[order[i]];
      v[i] = values[order[i]];
    }
    std::copy(k.begin(), k.end(), keys);
    std::copy(v.begin(), v.end(), values);
  }
};

}  // namespace

std::unique_ptr<RoundSession> makeEmulatedDeviceSession(Bvh bvh, const PrimitiveBoxes& prims,
                                                        const ParallelReinsertionOptimizer::Config& config,
                                                        const ParallelReinsertionOptimizer::Parallel& parallel) {
  return std::make_unique<reinsertion::BackendSession<SerialBackend>>(SerialBackend{}, std::move(bvh), prims, config,
                                                                      parallel);
}

InsertionOptimizer::Result optimizeEmulatedDevice(Bvh bvh, const PrimitiveBoxes& prims,
                                                  const ParallelReinsertionOptimizer::Config& config,
                                                  const ParallelReinsertionOptimizer::Parallel& parallel,
                                                  const LeafCollapser* collapse, std::size_t* deviceBytes) {
  const auto start = std::chrono::steady_clock::now();
  reinsertion::BackendSession<SerialBackend> session(SerialBackend{}, std::move(bvh), prims, config, parallel);
  InsertionOptimizer::Result result = runReinsertionRounds(session, config, collapse, start);
  if (deviceBytes) *deviceBytes = session.backend().allocated;
  return result;
}

}  // namespace tsah
