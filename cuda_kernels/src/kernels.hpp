#pragma once
// Host-side launchers of the runtime's kernels (defined in the .cu files). Every launcher checks the
// launch and throws CudaError; none synchronizes.
#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>

#include "device_types.hpp"

namespace tsah::cuda::detail {

// out[i] = (1 - alpha) * a[i] + alpha * b[i] for a = keyframes + params->a, b = keyframes + params->b,
// rounded exactly as anim::Animation::positionsAt does (alpha == 0 copies a).
void launchInterpolateFrame(const float* keyframes, const FrameParams* params, float* out, std::size_t count,
                            cudaStream_t stream);

// Bottom-up refit of an uploaded tree: one thread per leaf record, atomic counters per interior node
// (must be zero on entry); writes every child box, and root->box.
void launchRefit(GpuBvhNode* nodes, const uint32_t* nodeParent, const LeafRecord* leaves, uint32_t leafCount,
                 const uint32_t* triIndex, const uint32_t* indices, const float* positions, uint32_t* counters,
                 RootInfo* root, cudaStream_t stream);

// Woop triangle of every slot.
void launchWoop(const uint32_t* triIndex, uint32_t slots, const uint32_t* indices, const float* positions,
                WoopTriangle* woop, cudaStream_t stream);

// Traversal of `count` rays: closest hit into hits (when hits != nullptr) or any hit into
// occluded (1 = something hit). rayCounter: one device word, zero on entry (persistent launch).
void launchTrace(const TraceScene& scene, const Ray* rays, uint32_t count, Hit* hits, uint8_t* occluded,
                 uint32_t* rayCounter, const TraceLaunch& launch, cudaStream_t stream);

// Resident blocks per multiprocessor of the persistent traversal kernel.
int traceBlocksPerMultiprocessor(bool anyHit, uint32_t blockSize);

}  // namespace tsah::cuda::detail
