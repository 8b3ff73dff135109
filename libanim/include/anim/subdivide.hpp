#pragma once
// Uniform Loop subdivision of a static triangle mesh through OpenMesh's subdivider
// (OpenMesh/Tools/Subdivider/Uniform/LoopT.hh): every level splits each triangle into four and
// moves the vertices towards the limit surface, so dense environments can be made from the
// classic meshes.
#include <cstdint>

#include "anim/animation.hpp"

namespace anim {

struct MeshCounts {
  uint64_t vertices = 0, edges = 0, triangles = 0;
};

// The counts of `mesh` (unique undirected edges of its triangles).
MeshCounts meshCounts(const Animation& mesh);
// The counts after `levels` Loop levels: V' = V + E, E' = 2E + 3T, T' = 4T per level.
MeshCounts loopSubdividedCounts(MeshCounts counts, uint32_t levels);
// Bytes OpenMesh needs while subdividing to `counts` plus the resulting Animation (an estimate
// from the sizes of OpenMesh's connectivity and the subdivider's properties).
uint64_t loopSubdivisionBytes(const MeshCounts& counts);

// `levels` Loop levels of a one-keyframe animation. Triangles OpenMesh cannot link in (at a
// non-manifold edge or vertex) get their own copies of their vertices and subdivide on their own,
// so each level gives exactly 4x the triangles. Throws tsah::DataError when the mesh has several
// keyframes or a triangle repeats a vertex, tsah::Failure when OpenMesh fails to subdivide.
Animation subdivideLoop(const Animation& mesh, uint32_t levels);

}  // namespace anim
