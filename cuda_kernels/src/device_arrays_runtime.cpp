// GpuRuntime's device-array entry points: refit from positions in the caller's device memory and
// trace rays given as device arrays, ordered with the caller's stream by events (no host wait but
// a Wait check of device positions). docs/cuda-runtime.md#device-arrays.
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "cwbvh_kernels.hpp"
#include "device_array_checks.hpp"
#include "device_arrays.hpp"
#include "runtime_impl.hpp"
#include "tsah/base/coordinates.hpp"
#include "tsah/base/error.hpp"

namespace tsah::cuda {

// The events that order the runtime's stream with a caller's, the coordinate check's report and
// its answer in pinned host memory, and per tree the captured device update.
struct DeviceArrayState {
  // 0: the caller's stream reached the call; 1: the call's work is queued; 2: the answer's copy
  // forks beside the refit; 3: the answer is in `answer`.
  detail::EventTimer fences{4};
  // The first bad vertex (detail::kNoBadVertex between calls) and its coordinates.
  DeviceBuffer<uint32_t> report{4};
  uint32_t* answer = nullptr;  // pinned: the report of the last checked frame
  bool pending = false;        // `answer` of a queued check, not yet looked at
  struct Graph {
    GpuRuntime::Impl::CapturedGraph graph;
    detail::SourceNodes sourceNodes;
    const float* source = nullptr;  // the caller's buffer its nodes read (a caller mostly reuses one)
  };
  std::vector<Graph> graphs;  // per tree, captured at its first update from device positions
  DeviceArrayState(std::size_t trees, cudaStream_t stream) : graphs(trees) {
    // All four words: the answer's copy reads them even when no coordinate was bad.
    CUDA_CHECK(cudaMemsetAsync(report.data(), 0xff, report.bytes(), stream));
    CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&answer), report.bytes()));
  }
  ~DeviceArrayState() {
    for (Graph& g : graphs) GpuRuntime::Impl::destroy(g.graph);
    cudaFreeHost(answer);
  }
  DeviceArrayState(const DeviceArrayState&) = delete;
  DeviceArrayState& operator=(const DeviceArrayState&) = delete;
};

namespace {

constexpr const char* kRuntime = "GPU runtime";

DeviceArrayState& stateOf(GpuRuntime::Impl& m) {
  if (!m.deviceArrays) m.deviceArrays = std::make_shared<DeviceArrayState>(m.trees.size(), m.stream);
  return *m.deviceArrays;
}

// The runtime's stream waits for the work the caller queued on `caller` before the call ...
void followCaller(GpuRuntime::Impl& m, DeviceArrayState& s, cudaStream_t caller) {
  detail::orderAfter(s.fences, 0, caller, m.stream);
}

// ... and the caller's stream for the work the call queued (its side-stream part joins m.stream).
void handBack(GpuRuntime::Impl& m, DeviceArrayState& s, cudaStream_t caller) {
  detail::orderAfter(s.fences, 1, m.stream, caller);
}

// The check of `source` and its copy into the runtime's positions when every coordinate is good,
// then the report to the host and its reset; beside: on the side stream (beside the refit queued
// next), else on the runtime's stream. The copy is needed: tracing and rendering read the frame's
// positions after the caller may have reused its buffer. (A kernel that checked and copied at once
// would copy into a staging buffer that a guarded copy then moves: the same reads, one more write.)
void enqueueCheckedCopy(GpuRuntime::Impl& m, DeviceArrayState& s, const float* source, bool beside) {
  detail::launchFirstBadVertex(source, m.vertices, s.report.data(), m.stream);
  detail::launchCopyIfValid(source, m.positions.data(), m.vertices, s.report.data(), m.stream);
  cudaStream_t answer = m.stream;
  if (beside) {
    s.fences.mark(2, m.stream);
    s.fences.streamWait(2, m.sideStream);
    answer = m.sideStream;
  }
  CUDA_CHECK(cudaMemcpyAsync(s.answer, s.report.data(), s.report.bytes(), cudaMemcpyDeviceToHost, answer));
  CUDA_CHECK(cudaMemsetAsync(s.report.data(), 0xff, sizeof(uint32_t), answer));
}

// The whole update of a frame that is a refit of the current tree: a refused frame refits the
// unchanged positions again, which gives the same frame bit for bit. One captured graph per tree
// (the source set before each launch).
void enqueueGuardedUpdate(GpuRuntime::Impl& m, DeviceArrayState& s, const float* source) {
  const auto enqueue = [&] {
    enqueueCheckedCopy(m, s, source, true);
    m.enqueueRefitAndWoop();
  };
  if (!m.config.useGraphs) return enqueue();
  DeviceArrayState::Graph& g = s.graphs.at(m.current);
  if (!g.graph.exec) {
    g.graph = m.capture(enqueue);
    g.sourceNodes = detail::findSourceNodes(g.graph.graph);
    g.source = source;
  }
  if (g.source != source) {  // saves the two node updates' host time when the buffer is the last one
    detail::setSource(g.graph.exec, g.sourceNodes, source);
    g.source = source;
  }
  m.launch(g.graph);
}

tsah::DataError badVertexError(const uint32_t* answer) {
  float xyz[3];
  std::memcpy(xyz, answer + 1, sizeof xyz);
  const std::size_t c = firstBadCoordinate(xyz);
  return tsah::DataError("positions: vertex " + std::to_string(answer[0]) + " " + describeBadCoordinate(xyz[c < 3 ? c : 0]));
}

}  // namespace

void GpuRuntime::Impl::throwRefusedDeviceUpdate() {
  if (!deviceArrays || !deviceArrays->pending) return;
  DeviceArrayState& s = *deviceArrays;
  s.fences.wait(3);
  s.pending = false;
  if (s.answer[0] != detail::kNoBadVertex) throw badVertexError(s.answer);
}

void GpuRuntime::checkDeviceUpdate() { impl_->throwRefusedDeviceUpdate(); }

void GpuRuntime::updateFromDevice(const float* devicePositions, std::size_t vertexCount, StreamHandle stream,
                                  DeviceCheck check) {
  Impl& m = *impl_;
  if (vertexCount != m.vertices)
    throw tsah::DataError("GPU runtime: got " + std::to_string(vertexCount) + " vertices, expected " +
                          std::to_string(m.vertices));
  detail::requireDeviceMemory(devicePositions, m.config.device, kRuntime, "positions");
  m.throwRefusedDeviceUpdate();
  DeviceArrayState& s = stateOf(m);
  const auto caller = static_cast<cudaStream_t>(stream);
  followCaller(m, s, caller);
  // Refitting the current tree again leaves another traced frame (a rebuilt tree, a blurred
  // frame, another tree's) changed: such a frame waits for the check before the refit is queued.
  const bool guarded = m.tracingRefitOfCurrentTree();
  if (guarded) {
    enqueueGuardedUpdate(m, s, devicePositions);
  } else {
    enqueueCheckedCopy(m, s, devicePositions, false);
    s.fences.mark(3, m.stream);
    s.pending = true;
    m.throwRefusedDeviceUpdate();
    m.enqueueRefitAndWoop();
  }
  s.fences.mark(3, m.stream);
  s.pending = true;
  handBack(m, s, caller);
  if (check == DeviceCheck::Wait) m.throwRefusedDeviceUpdate();
  // As update(positions): the static vertices may have moved, the next updateAt refits everything.
  // (After a refused Deferred frame these are only conservative: the positions are unchanged.)
  m.restInPlace = false;
  m.tree().staticBoxesValid = false;
  m.woopTree = -1;
  m.markUpdated();
}

void GpuRuntime::closestHitsOnDevice(const DeviceRays& rays, const DeviceHits& hits, StreamHandle stream) {
  Impl& m = *impl_;
  m.requireTraceable();
  const detail::ArrayRays a = detail::checkedArrayRays(rays, m.config.device, kRuntime);
  if (a.count == 0) return;
  const std::pair<const void*, const char*> outputs[] = {
      {hits.t, "t"}, {hits.u, "u"}, {hits.v, "v"}, {hits.triangle, "triangle"}};
  for (const auto& [p, name] : outputs)
    if (p) detail::requireDeviceMemory(p, m.config.device, kRuntime, name);
  DeviceArrayState& s = stateOf(m);
  const auto caller = static_cast<cudaStream_t>(stream);
  followCaller(m, s, caller);
  detail::launchArrayTrace(m.scene(), a, {hits.t, hits.u, hits.v, hits.triangle}, nullptr, m.stream);
  handBack(m, s, caller);
}

void GpuRuntime::anyHitsOnDevice(const DeviceRays& rays, uint8_t* occluded, StreamHandle stream) {
  Impl& m = *impl_;
  m.requireTraceable();
  const detail::ArrayRays a = detail::checkedArrayRays(rays, m.config.device, kRuntime);
  if (a.count == 0) return;
  detail::requireDeviceMemory(occluded, m.config.device, kRuntime, "occluded");
  DeviceArrayState& s = stateOf(m);
  const auto caller = static_cast<cudaStream_t>(stream);
  followCaller(m, s, caller);
  detail::launchArrayTrace(m.scene(), a, {}, occluded, m.stream);
  handBack(m, s, caller);
}

namespace detail {

void requireDeviceMemory(const void* p, int device, const char* runtime, const char* name) {
  const std::string prefix = std::string(runtime) + ": " + name + ": ";
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

ArrayRays checkedArrayRays(const GpuRuntime::DeviceRays& r, int device, const char* runtime) {
  const std::string prefix = std::string(runtime) + ": ";
  if (r.count > 0xffffffffu) throw tsah::ConfigError(prefix + "too many rays in one call");
  if (!r.tmin && !(std::isfinite(r.tminValue) && r.tminValue >= 0.0f))
    throw tsah::ConfigError(prefix + "tmin must be finite and >= 0");
  if (!r.tmax && std::isnan(r.tmaxValue)) throw tsah::ConfigError(prefix + "tmax is NaN");
  ArrayRays a;
  a.count = static_cast<uint32_t>(r.count);
  if (a.count == 0) return a;
  requireDeviceMemory(r.origins, device, runtime, "origins");
  requireDeviceMemory(r.directions, device, runtime, "directions");
  if (r.tmin) requireDeviceMemory(r.tmin, device, runtime, "tmin");
  if (r.tmax) requireDeviceMemory(r.tmax, device, runtime, "tmax");
  a.origins = r.origins;
  a.directions = r.directions;
  a.tmin = r.tmin;
  a.tmax = r.tmax;
  a.tminValue = r.tminValue;
  a.tmaxValue = r.tmaxValue;
  return a;
}

}  // namespace detail

}  // namespace tsah::cuda
