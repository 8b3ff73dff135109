#pragma once
// What the runtimes' device-array entry points (device_arrays_runtime.cpp,
// two_level_device_arrays.cpp) share: the checks of the caller's pointers, done before anything is
// queued, and the ordering of a runtime's stream with the caller's by events (no host wait).
#include <cuda_runtime_api.h>

#include <cstddef>

#include "device_arrays.hpp"
#include "event_timer.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace tsah::cuda::detail {

// Throws tsah::ConfigError ("RUNTIME: NAME: problem") unless p is device (or managed) memory that
// `device` reads: a host pointer or another device's memory would fault inside a kernel.
void requireDeviceMemory(const void* p, int device, const char* runtime, const char* name);

// The caller's rays as the kernels read them, after checking the count (at most 2^32 - 1), the
// scalar limits and every array's pointer (requireDeviceMemory; none when there are no rays).
ArrayRays checkedArrayRays(const GpuRuntime::DeviceRays& rays, int device, const char* runtime);

// `after`'s later work runs after the work queued on `before` so far (event e of fences).
inline void orderAfter(EventTimer& fences, std::size_t e, cudaStream_t before, cudaStream_t after) {
  fences.mark(e, before);
  fences.streamWait(e, after);
}

}  // namespace tsah::cuda::detail
