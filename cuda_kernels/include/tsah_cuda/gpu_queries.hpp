#pragma once
// Queries beyond rays on the GPU runtime's current frame (the CPU's: tsah/runtime/queries.hpp, the
// same traversal, layout/proximity.hpp, compiled for the device without fused multiply-adds, so
// the answers equal the CPU runtime's bit for bit). They read the refitted binary tree (layout
// bvh2, or the tree of the last rebuild) and throw tsah::ConfigError for layout cwbvh, whose
// update does not refit the binary boxes, and before there is a frame to trace. Inputs are checked
// as on the CPU (tsah::checkPointQueries / checkBoxQueries). Each call uploads the queries, runs
// its kernels on the runtime's stream and waits for the answers.
#include <span>
#include <vector>

#include "tsah/runtime/queries.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace tsah::cuda {

// One thread per point. stats (optional): query count and the kernel's device time.
std::vector<PointHit> closestPoints(GpuRuntime& runtime, std::span<const Vec3> points, std::span<const float> radii,
                                    RayPassStats* stats = nullptr);

// Two passes, one thread per box: count, then (after a prefix sum of the counts) fill; ids sorted
// ascending per query as on the CPU. stats: query count and both kernels' device time.
BoxOverlaps overlappingTriangles(GpuRuntime& runtime, std::span<const Aabb> boxes, RayPassStats* stats = nullptr);

}  // namespace tsah::cuda
