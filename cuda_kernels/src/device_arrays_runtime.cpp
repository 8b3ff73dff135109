// GpuRuntime's device-array entry points: refit from positions in the caller's device memory and
// trace rays given as device arrays, ordered with the caller's stream by events (no host wait but
// the coordinate check's 4-byte answer). docs/cuda-runtime.md#device-arrays.
#include <cmath>
#include <memory>
#include <string>
#include <utility>

#include "cwbvh_kernels.hpp"
#include "device_arrays.hpp"
#include "runtime_impl.hpp"
#include "tsah/base/coordinates.hpp"
#include "tsah/base/error.hpp"

namespace tsah::cuda {

// The events that order the runtime's stream with a caller's, and the coordinate check's answer
// (one device word, read back into pinned host memory).
struct DeviceArrayState {
  detail::EventTimer fences{2};  // 0: the caller's stream reached the call; 1: the call's work is queued
  DeviceBuffer<uint32_t> firstBad{1};
  uint32_t* answer = nullptr;  // pinned
  DeviceArrayState() { CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&answer), sizeof *answer)); }
  ~DeviceArrayState() { cudaFreeHost(answer); }
  DeviceArrayState(const DeviceArrayState&) = delete;
  DeviceArrayState& operator=(const DeviceArrayState&) = delete;
};

namespace {

constexpr uint32_t kNoBadVertex = 0xffffffffu;

DeviceArrayState& stateOf(GpuRuntime::Impl& m) {
  if (!m.deviceArrays) m.deviceArrays = std::make_shared<DeviceArrayState>();
  return *m.deviceArrays;
}

// Throws tsah::ConfigError naming `name` unless p is device (or managed) memory that the runtime's
// device reads: a host pointer or another device's memory would fault inside a kernel.
void requireDeviceMemory(const void* p, int device, const char* name) {
  const std::string prefix = std::string("GPU runtime: ") + name + ": ";
  if (!p) throw tsah::ConfigError(prefix + "a null pointer");
  cudaPointerAttributes a{};
  if (cudaPointerGetAttributes(&a, p) != cudaSuccess) {
    cudaGetLastError();  // clear the error this query leaves behind
    throw tsah::ConfigError(prefix + "not a pointer that CUDA knows");
  }
  if (a.type == cudaMemoryTypeManaged) return;
  if (a.type != cudaMemoryTypeDevice)
    throw tsah::ConfigError(prefix + "host memory, not device memory");
  if (a.device != device)
    throw tsah::ConfigError(prefix + "memory of device " + std::to_string(a.device) + "; the runtime uses device " +
                            std::to_string(device));
}

// The runtime's stream waits for the work the caller queued on `caller` before the call ...
void followCaller(GpuRuntime::Impl& m, DeviceArrayState& s, cudaStream_t caller) {
  s.fences.mark(0, caller);
  s.fences.streamWait(0, m.stream);
}

// ... and the caller's stream for the work the call queued (its side-stream part joins m.stream).
void handBack(GpuRuntime::Impl& m, DeviceArrayState& s, cudaStream_t caller) {
  s.fences.mark(1, m.stream);
  s.fences.streamWait(1, caller);
}

detail::ArrayRays arrayRays(const GpuRuntime::DeviceRays& r, int device) {
  if (r.count > 0xffffffffu) throw tsah::ConfigError("GPU runtime: too many rays in one call");
  if (!r.tmin && !(std::isfinite(r.tminValue) && r.tminValue >= 0.0f))
    throw tsah::ConfigError("GPU runtime: tmin must be finite and >= 0");
  if (!r.tmax && std::isnan(r.tmaxValue)) throw tsah::ConfigError("GPU runtime: tmax is NaN");
  detail::ArrayRays a;
  a.count = static_cast<uint32_t>(r.count);
  if (a.count == 0) return a;
  requireDeviceMemory(r.origins, device, "origins");
  requireDeviceMemory(r.directions, device, "directions");
  if (r.tmin) requireDeviceMemory(r.tmin, device, "tmin");
  if (r.tmax) requireDeviceMemory(r.tmax, device, "tmax");
  a.origins = r.origins;
  a.directions = r.directions;
  a.tmin = r.tmin;
  a.tmax = r.tmax;
  a.tminValue = r.tminValue;
  a.tmaxValue = r.tmaxValue;
  return a;
}

}  // namespace

void GpuRuntime::updateFromDevice(const float* devicePositions, std::size_t vertexCount, StreamHandle stream) {
  Impl& m = *impl_;
  if (vertexCount != m.vertices)
    throw tsah::DataError("GPU runtime: got " + std::to_string(vertexCount) + " vertices, expected " +
                          std::to_string(m.vertices));
  requireDeviceMemory(devicePositions, m.config.device, "positions");
  DeviceArrayState& s = stateOf(m);
  const auto caller = static_cast<cudaStream_t>(stream);
  followCaller(m, s, caller);
  CUDA_CHECK(cudaMemsetAsync(s.firstBad.data(), 0xff, sizeof(uint32_t), m.stream));
  detail::launchFirstBadVertex(devicePositions, m.vertices, s.firstBad.data(), m.stream);
  CUDA_CHECK(cudaMemcpyAsync(s.answer, s.firstBad.data(), sizeof(uint32_t), cudaMemcpyDeviceToHost, m.stream));
  CUDA_CHECK(cudaStreamSynchronize(m.stream));  // the call's one wait
  if (const uint32_t bad = *s.answer; bad != kNoBadVertex) {
    float xyz[3];
    CUDA_CHECK(cudaMemcpy(xyz, devicePositions + 3 * std::size_t(bad), sizeof xyz, cudaMemcpyDeviceToHost));
    const std::size_t c = firstBadCoordinate(xyz);
    throw tsah::DataError("positions: vertex " + std::to_string(bad) + " " + describeBadCoordinate(xyz[c < 3 ? c : 0]));
  }
  m.events.record(0, m.stream);  // timed as update(positions)'s upload
  CUDA_CHECK(cudaMemcpyAsync(m.positions.data(), devicePositions, m.positions.bytes(), cudaMemcpyDeviceToDevice,
                             m.stream));
  m.restInPlace = false;
  m.events.record(1, m.stream);
  m.enqueueRefitAndWoop();
  // As update(positions): the static vertices may have moved, the next updateAt refits everything.
  m.tree().staticBoxesValid = false;
  m.woopTree = -1;
  m.markUpdated();
  handBack(m, s, caller);
}

void GpuRuntime::closestHitsOnDevice(const DeviceRays& rays, const DeviceHits& hits, StreamHandle stream) {
  Impl& m = *impl_;
  m.requireTraceable();
  const detail::ArrayRays a = arrayRays(rays, m.config.device);
  if (a.count == 0) return;
  const std::pair<const void*, const char*> outputs[] = {
      {hits.t, "t"}, {hits.u, "u"}, {hits.v, "v"}, {hits.triangle, "triangle"}};
  for (const auto& [p, name] : outputs)
    if (p) requireDeviceMemory(p, m.config.device, name);
  DeviceArrayState& s = stateOf(m);
  const auto caller = static_cast<cudaStream_t>(stream);
  followCaller(m, s, caller);
  detail::launchArrayTrace(m.scene(), a, {hits.t, hits.u, hits.v, hits.triangle}, nullptr, m.stream);
  handBack(m, s, caller);
}

void GpuRuntime::anyHitsOnDevice(const DeviceRays& rays, uint8_t* occluded, StreamHandle stream) {
  Impl& m = *impl_;
  m.requireTraceable();
  const detail::ArrayRays a = arrayRays(rays, m.config.device);
  if (a.count == 0) return;
  requireDeviceMemory(occluded, m.config.device, "occluded");
  DeviceArrayState& s = stateOf(m);
  const auto caller = static_cast<cudaStream_t>(stream);
  followCaller(m, s, caller);
  detail::launchArrayTrace(m.scene(), a, {}, occluded, m.stream);
  handBack(m, s, caller);
}

}  // namespace tsah::cuda
