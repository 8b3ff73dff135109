#pragma once
// The blurred frame's trace on the device (blurred_traversal.cu): the frame as tsah::MotionBvhView
// (device pointers), traced by the binary layout's device loop with the CPU runtime's lerps.
#include <cstdint>
#include <cuda_runtime_api.h>

#include "device_types.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah::cuda::detail {

// Traces rays[i] at shutter fraction times[i]: closest hits into `hits`, or (occluded non-null)
// any hits into `occluded`.
void launchBlurredTrace(const MotionBvhView& frame, const Ray* rays, const float* times, uint32_t count, Hit* hits,
                        uint8_t* occluded, cudaStream_t stream);

}  // namespace tsah::cuda::detail
