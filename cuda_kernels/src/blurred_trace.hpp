#pragma once
// The blurred frame's trace on the device (blurred_traversal.cu): what the host passes to it.
#include <cstdint>
#include <cuda_runtime_api.h>

#include "device_types.hpp"
#include "tsah/core/ray.hpp"

namespace tsah::cuda::detail {

// A blurred frame on the device: keys * interiorCount nodes (key-major), keys roots, keys *
// vertexCoords positions, keys increasing fractions (first 0, last 1).
struct BlurredScene {
  const GpuBvhNode* keyNodes = nullptr;
  const RootInfo* keyRoots = nullptr;
  const float* keyPositions = nullptr;
  const float* keyTimes = nullptr;
  const uint32_t* triIndex = nullptr;
  const uint32_t* indices = nullptr;
  uint32_t keys = 0, interiorCount = 0;
  uint64_t vertexCoords = 0;
};

// Traces rays[i] at shutter fraction times[i]: closest hits into `hits`, or (occluded non-null)
// any hits into `occluded`.
void launchBlurredTrace(const BlurredScene& scene, const Ray* rays, const float* times, uint32_t count, Hit* hits,
                        uint8_t* occluded, cudaStream_t stream);

}  // namespace tsah::cuda::detail
