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

// Throws tsah::DataError naming the mesh and the first offending triangle unless the mesh is what a
// half-edge mesh can hold: no triangle repeats a vertex, every edge has at most two triangles, and
// the triangles are consistently oriented (each directed edge is walked by at most one triangle).
void checkSubdivisionTopology(const Animation& mesh);

// `levels` Loop levels of a one-keyframe animation. The mesh must pass checkSubdivisionTopology; a
// triangle OpenMesh still cannot link in (at a non-manifold vertex) gets its own copies of its
// vertices and subdivides on its own, so each level gives exactly 4x the triangles; vertices no
// triangle uses are left out. Throws
// tsah::DataError when the mesh has several keyframes or fails the check, tsah::Failure when
// OpenMesh fails to subdivide.
Animation subdivideLoop(const Animation& mesh, uint32_t levels);

}  // namespace anim
