#pragma once
// Owning device memory (RAII, move-only) and the trivially copyable views that kernels take by value.
#include <cuda_runtime_api.h>

#include <cstddef>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah_cuda/cuda_check.hpp"

namespace tsah::cuda {

// A pointer and a count: what a kernel needs of a buffer. Never owns anything.
template <typename T>
struct DeviceSpan {
  T* data = nullptr;
  std::size_t size = 0;
};

template <typename T>
class DeviceBuffer {
  static_assert(std::is_trivially_copyable_v<T>, "device buffers hold plain data");

 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(std::size_t count) { allocate(count); }
  explicit DeviceBuffer(std::span<const T> host, cudaStream_t stream = nullptr) {
    allocate(host.size());
    upload(host, stream);
  }
  ~DeviceBuffer() { release(); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& other) noexcept
      : data_(std::exchange(other.data_, nullptr)), size_(std::exchange(other.size_, 0)) {}
  DeviceBuffer& operator=(DeviceBuffer&& other) noexcept {
    if (this != &other) {
      release();
      data_ = std::exchange(other.data_, nullptr);
      size_ = std::exchange(other.size_, 0);
    }
    return *this;
  }

  // Discards the contents; allocates only when the count changes.
  void resize(std::size_t count) {
    if (count == size_) return;
    release();
    allocate(count);
  }
  // Grows (discarding the contents) when fewer than `count` elements are held.
  void reserve(std::size_t count) {
    if (count > size_) resize(count);
  }

  T* data() { return data_; }
  const T* data() const { return data_; }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  std::size_t bytes() const { return size_ * sizeof(T); }
  DeviceSpan<T> view() { return {data_, size_}; }
  DeviceSpan<const T> view() const { return {data_, size_}; }

  // Copies host data into the first host.size() elements (asynchronous on `stream` for pinned
  // memory; pageable host memory makes it synchronous with respect to the host).
  void upload(std::span<const T> host, cudaStream_t stream = nullptr) {
    if (host.size() > size_)
      throw tsah::ConfigError("DeviceBuffer: upload of " + std::to_string(host.size()) + " elements into a buffer of " +
                              std::to_string(size_));
    if (host.empty()) return;
    CUDA_CHECK(cudaMemcpyAsync(data_, host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice, stream));
  }
  // Copies the first `count` elements (all when count is npos) to the host; waits for `stream`.
  std::vector<T> download(cudaStream_t stream = nullptr, std::size_t count = std::size_t(-1)) const {
    if (count == std::size_t(-1)) count = size_;
    if (count > size_) throw tsah::ConfigError("DeviceBuffer: download past the end of the buffer");
    std::vector<T> host(count);
    if (count == 0) return host;
    CUDA_CHECK(cudaMemcpyAsync(host.data(), data_, count * sizeof(T), cudaMemcpyDeviceToHost, stream));
    CUDA_CHECK(cudaStreamSynchronize(stream));
    return host;
  }
  void fillBytes(int value, cudaStream_t stream = nullptr) {
    if (size_ > 0) CUDA_CHECK(cudaMemsetAsync(data_, value, bytes(), stream));
  }

 private:
  void allocate(std::size_t count) {
    if (count == 0) return;
    void* p = nullptr;
    CUDA_CHECK(cudaMalloc(&p, count * sizeof(T)));
    data_ = static_cast<T*>(p);
    // Zeroed once: struct padding and slots a kernel leaves unwritten are then defined when they
    // are copied back (compute-sanitizer initcheck), and no stale data of an earlier buffer shows.
    // Waited for here: the legacy stream does not order with the runtime's non-blocking streams,
    // so an unwaited memset could land after an upload that follows on another stream.
    CUDA_CHECK(cudaMemsetAsync(p, 0, count * sizeof(T), nullptr));
    CUDA_CHECK(cudaStreamSynchronize(nullptr));
    size_ = count;
  }
  void release() noexcept {
    if (data_) cudaFree(data_);  // never throws from a destructor; a failed free leaks at worst
    data_ = nullptr;
    size_ = 0;
  }

  T* data_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace tsah::cuda
