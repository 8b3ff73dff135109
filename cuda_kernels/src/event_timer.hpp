#pragma once
// A fixed set of CUDA events recorded on one stream; elapsed device time between any two of them.
#include <cuda_runtime_api.h>

#include <cstddef>
#include <vector>

#include "tsah_cuda/cuda_check.hpp"

namespace tsah::cuda::detail {

class EventTimer {
 public:
  EventTimer() = default;  // no events: touches no device
  explicit EventTimer(std::size_t count) { create(count); }
  ~EventTimer() { destroy(); }
  // Replaces the events by `count` new ones (on the current device).
  void create(std::size_t count) {
    destroy();
    events_.assign(count, nullptr);
    for (auto& e : events_) CUDA_CHECK(cudaEventCreate(&e));
  }
  EventTimer(const EventTimer&) = delete;
  EventTimer& operator=(const EventTimer&) = delete;

  std::size_t size() const { return events_.size(); }
  // Inside a stream capture the record must be "external" to become an event-record node of the
  // graph (a plain record only adds a dependency there), so graph launches are timed too; outside
  // a capture that flag is refused.
  void record(std::size_t i, cudaStream_t stream) {
    cudaStreamCaptureStatus status = cudaStreamCaptureStatusNone;
    CUDA_CHECK(cudaStreamIsCapturing(stream, &status));
    if (status == cudaStreamCaptureStatusActive)
      CUDA_CHECK(cudaEventRecordWithFlags(events_.at(i), stream, cudaEventRecordExternal));
    else
      CUDA_CHECK(cudaEventRecord(events_.at(i), stream));
  }
  // Records event i for a fork or join between streams only (never timed): a plain record, which
  // inside a capture becomes a dependency of the graph.
  void mark(std::size_t i, cudaStream_t stream) { CUDA_CHECK(cudaEventRecord(events_.at(i), stream)); }
  void wait(std::size_t i) { CUDA_CHECK(cudaEventSynchronize(events_.at(i))); }
  // Makes `stream` wait for event i (recorded on another stream): a fork or join between streams.
  void streamWait(std::size_t i, cudaStream_t stream) { CUDA_CHECK(cudaStreamWaitEvent(stream, events_.at(i), 0)); }
  // Device milliseconds from event a to event b; both must have completed (wait on the later one).
  double ms(std::size_t a, std::size_t b) const {
    float v = 0.0f;
    CUDA_CHECK(cudaEventElapsedTime(&v, events_.at(a), events_.at(b)));
    return double(v);
  }

 private:
  void destroy() noexcept {
    for (auto e : events_)
      if (e) cudaEventDestroy(e);
    events_.clear();
  }
  std::vector<cudaEvent_t> events_;
};

}  // namespace tsah::cuda::detail
