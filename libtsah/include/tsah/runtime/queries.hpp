#pragma once
// Queries beyond rays on a CPU runtime's current frame, in whichever layout it traces (bvh2 from
// the binary tree, bvh4 / bvh8 from the wide trees, whose boxes every update() refits), parallel
// over the queries on the runtime's threads (the traversal: layout/proximity.hpp).
//
// - closestPoints: for each point, the closest point on the mesh within its radius (distance <=
//   radius): triangle, barycentrics, point and distance; a miss has triangle kNoHit and distance
//   +inf. At equal distance the lowest triangle id wins, so every layout gives the same answer.
// - overlappingTriangles: for each query box, the triangles whose box in the current frame
//   overlaps it (closed intervals: touching counts), as CSR: ids of query q in
//   triangles[offsets[q], offsets[q + 1]), ascending. These are candidates by triangle box (as
//   NVIDIA Warp's mesh_query_aabb reports), not an exact triangle-box test.
#include <cstdint>
#include <span>
#include <vector>

#include "tsah/core/aabb.hpp"
#include "tsah/layout/proximity.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace tsah {

struct BoxOverlaps {
  std::vector<uint64_t> offsets;    // queries + 1 entries, offsets[0] = 0
  std::vector<uint32_t> triangles;  // triangle ids, ascending within each query
};

// radii: one radius for every point, or one per point; each >= 0 (+inf: no limit). Throws
// tsah::ConfigError for a point with a non-finite coordinate, a negative or NaN radius, or a radius
// count that is neither 1 nor the point count.
std::vector<PointHit> closestPoints(const CpuRuntime& runtime, std::span<const Vec3> points,
                                    std::span<const float> radii);

// Throws tsah::ConfigError for a box with a NaN coordinate or lo > hi on an axis (infinite bounds
// are allowed).
BoxOverlaps overlappingTriangles(const CpuRuntime& runtime, std::span<const Aabb> boxes);

// The checks above, shared with the GPU entry points.
void checkPointQueries(std::span<const Vec3> points, std::span<const float> radii);
void checkBoxQueries(std::span<const Aabb> boxes);

}  // namespace tsah
