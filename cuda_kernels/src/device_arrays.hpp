#pragma once
// Launchers of the kernels behind GpuRuntime's device-array entry points (device_arrays.cu):
// the coordinate check of a caller's position buffer and the traversal of rays given as separate
// (n, 3) arrays. Each checks its launch and throws CudaError; none synchronizes.
#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>

#include "device_types.hpp"

namespace tsah::cuda::detail {

// Rays as the caller's arrays hold them (GpuRuntime::DeviceRays with a 32-bit count).
struct ArrayRays {
  const float* origins = nullptr;     // 3 floats per ray
  const float* directions = nullptr;  // 3 floats per ray
  const float* tmin = nullptr;        // 1 float per ray, or null: tminValue
  const float* tmax = nullptr;        // 1 float per ray, or null: tmaxValue
  float tminValue = 0.0f, tmaxValue = 0.0f;
  uint32_t count = 0;
};

// Per-ray times (shutter fractions) as the caller's array holds them, or, when null, one value.
struct ArrayTimes {
  const float* times = nullptr;
  float value = 0.0f;
};

// Closest-hit results, one value per ray in each non-null array.
struct ArrayHits {
  float* t = nullptr;
  float* u = nullptr;
  float* v = nullptr;
  uint32_t* triangle = nullptr;
};

// *firstBad = min(*firstBad, the lowest vertex with a coordinate that is NaN, infinite or beyond
// tsah::kMaxCoordinate) over `vertexCount` vertices of 3 floats (tsah::firstBadCoordinate / 3);
// set *firstBad to 0xffffffff first.
void launchFirstBadVertex(const float* positions, uint32_t vertexCount, uint32_t* firstBad, cudaStream_t stream);

// The answer of launchFirstBadVertex when every vertex is good.
inline constexpr uint32_t kNoBadVertex = 0xffffffffu;

// After launchFirstBadVertex(source, vertexCount, report): copies source into target (vertexCount
// * 3 floats) when report[0] is kNoBadVertex; otherwise leaves target and stores the first bad
// vertex's three coordinates in report[1..3] (as floats). report: 4 device words.
void launchCopyIfValid(const float* source, float* target, uint32_t vertexCount, uint32_t* report,
                       cudaStream_t stream);

// The two kernel nodes of a graph captured around launchFirstBadVertex and launchCopyIfValid, and
// the change of their source (the caller's positions) before a launch of its executable. A node
// is null when the graph lacks it (no vertices). The arguments' storage lives as long as the graph.
struct SourceNodes {
  struct Node {
    cudaGraphNode_t node = nullptr;
    cudaKernelNodeParams launch{};
  };
  Node check, copy;
};
SourceNodes findSourceNodes(cudaGraph_t graph);
void setSource(cudaGraphExec_t exec, const SourceNodes& nodes, const float* source);

// Closest hits (hits) or occlusion flags (occluded != nullptr: 1 = something hit) of the rays against
// the scene (either layout), one thread per ray. A miss writes t = +inf, u = v = 0, triangle = kNoHit.
void launchArrayTrace(const TraceScene& scene, const ArrayRays& rays, const ArrayHits& hits, uint8_t* occluded,
                      cudaStream_t stream);

}  // namespace tsah::cuda::detail
