// GpuTwoLevelRuntime's device-array queries (docs/cuda-runtime.md#device-arrays): rays, times and
// results in the caller's device memory, traced on the runtime's stream between two events that
// order it with the caller's stream (no host wait), as GpuRuntime's device-array traces are.
#include <memory>
#include <utility>

#include "device_array_checks.hpp"
#include "tsah/base/error.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "two_level_blur.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda {

namespace {
constexpr const char* kRuntime = "GPU two-level runtime";
}

template <bool AnyHit>
void GpuTwoLevelRuntime::traceOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceTimes* times,
                                       const DeviceHits& hits, uint8_t* occluded, StreamHandle stream) {
  const int device = this->device().index;
  const detail::ArrayRays a = detail::checkedArrayRays(rays, device, kRuntime);
  if (a.count == 0) return;
  if constexpr (AnyHit) {
    detail::requireDeviceMemory(occluded, device, kRuntime, "occluded");
  } else {
    const std::pair<const void*, const char*> outputs[] = {
        {hits.t, "t"}, {hits.u, "u"}, {hits.v, "v"}, {hits.instance, "instance"}, {hits.triangle, "triangle"}};
    for (const auto& [p, name] : outputs)
      if (p) detail::requireDeviceMemory(p, device, kRuntime, name);
  }
  const detail::TwoLevelTraceAccess access = traceAccess();
  const bool timed = times && access.blurred;
  if (timed && times->times) detail::requireDeviceMemory(times->times, device, kRuntime, "times");
  if (!callerFences_) callerFences_ = std::make_unique<detail::EventTimer>(2);
  const auto caller = static_cast<cudaStream_t>(stream);
  detail::orderAfter(*callerFences_, 0, caller, access.stream);
  const detail::ArrayInstanceHits out{hits.t, hits.u, hits.v, hits.instance, hits.triangle};
  if (timed)
    detail::launchBlurredTwoLevelArrayTrace(*access.blurred, a, {times->times, times->value}, out, occluded,
                                            access.stream);
  else
    detail::launchTwoLevelArrayTrace(access.scene, a, out, occluded, access.stream);
  detail::orderAfter(*callerFences_, 1, access.stream, caller);
}

void GpuTwoLevelRuntime::closestHitsOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceHits& hits,
                                             StreamHandle stream) {
  traceOnDevice<false>(rays, nullptr, hits, nullptr, stream);
}

void GpuTwoLevelRuntime::closestHitsOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceTimes& times,
                                             const DeviceHits& hits, StreamHandle stream) {
  traceOnDevice<false>(rays, &times, hits, nullptr, stream);
}

void GpuTwoLevelRuntime::anyHitsOnDevice(const GpuRuntime::DeviceRays& rays, uint8_t* occluded, StreamHandle stream) {
  traceOnDevice<true>(rays, nullptr, {}, occluded, stream);
}

void GpuTwoLevelRuntime::anyHitsOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceTimes& times,
                                         uint8_t* occluded, StreamHandle stream) {
  traceOnDevice<true>(rays, &times, {}, occluded, stream);
}

}  // namespace tsah::cuda
