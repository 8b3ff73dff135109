#include "anim/subdivide.hpp"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>
#include <algorithm>
#include <vector>

#include "tsah/base/error.hpp"

namespace anim {

namespace {

using Mesh = OpenMesh::TriMesh_ArrayKernelT<>;

}  // namespace

MeshCounts meshCounts(const Animation& mesh) {
  const auto idx = mesh.indices();
  std::vector<uint64_t> edges;
  edges.reserve(idx.size());
  for (std::size_t t = 0; t < idx.size(); t += 3)
    for (int e = 0; e < 3; ++e) {
      const uint64_t a = idx[t + e], b = idx[t + (e + 1) % 3];
      edges.push_back(std::min(a, b) << 32 | std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  const auto unique = std::unique(edges.begin(), edges.end()) - edges.begin();
  return {mesh.vertexCount(), uint64_t(unique), mesh.triangleCount()};
}

MeshCounts loopSubdividedCounts(MeshCounts c, uint32_t levels) {
  for (uint32_t l = 0; l < levels; ++l) c = {c.vertices + c.edges, 2 * c.edges + 3 * c.triangles, 4 * c.triangles};
  return c;
}

uint64_t loopSubdivisionBytes(const MeshCounts& c) {
  // OpenMesh's array kernel: per vertex a point (12), its halfedge (4), status (4) and the
  // subdivider's new-point property (12); per edge two halfedges (4 handles each) + status and the
  // edge-point property; per face a halfedge + status. Vectors grow by doubling: x1.5 on average.
  const uint64_t openMesh = c.vertices * 32 + c.edges * (2 * 16 + 4 + 12) + c.triangles * 8;
  const uint64_t result = c.vertices * 12 + c.triangles * 12;
  return openMesh * 3 / 2 + result;
}

Animation subdivideLoop(const Animation& source, uint32_t levels) {
  const std::string who = source.name().empty() ? std::string("mesh") : source.name();
  if (source.keyframeCount() != 1)
    throw tsah::DataError(who + ": subdivision needs a static mesh (this one has " +
                          std::to_string(source.keyframeCount()) + " keyframes)");
  if (levels == 0) return source;
  Mesh mesh;
  const std::vector<float> p = source.keyframe(0);
  std::vector<Mesh::VertexHandle> vh(source.vertexCount());
  for (uint32_t v = 0; v < source.vertexCount(); ++v) vh[v] = mesh.add_vertex(Mesh::Point(p[3 * v], p[3 * v + 1], p[3 * v + 2]));
  const auto idx = source.indices();
  // A triangle OpenMesh cannot link in (a non-manifold edge or vertex) gets its own copies of its
  // vertices, so it subdivides on its own instead of failing the mesh. OpenMesh reports each such
  // face on its error stream; libraries never print, so that stream is off meanwhile.
  std::size_t rejected = 0;
  omerr().disable();
  for (std::size_t t = 0; t < idx.size(); t += 3) {
    if (mesh.add_face(vh[idx[t]], vh[idx[t + 1]], vh[idx[t + 2]]).is_valid()) continue;
    Mesh::VertexHandle own[3];
    for (int c = 0; c < 3; ++c) own[c] = mesh.add_vertex(mesh.point(vh[idx[t + c]]));
    if (!mesh.add_face(own[0], own[1], own[2]).is_valid()) ++rejected;
  }
  omerr().enable();
  if (rejected > 0)
    throw tsah::DataError(who + ": cannot subdivide: " + std::to_string(rejected) +
                          " triangles repeat a vertex (OpenMesh cannot represent them)");
  OpenMesh::Subdivider::Uniform::LoopT<Mesh> loop;
  if (!loop.attach(mesh) || !loop(levels)) throw tsah::Failure(who + ": Loop subdivision failed");
  loop.detach();
  std::vector<float> positions(mesh.n_vertices() * 3);
  for (const auto v : mesh.vertices()) {
    const auto& q = mesh.point(v);
    std::copy_n(q.data(), 3, positions.data() + 3 * std::size_t(v.idx()));
  }
  std::vector<uint32_t> indices;
  indices.reserve(mesh.n_faces() * 3);
  for (const auto f : mesh.faces())
    for (const auto v : mesh.fv_range(f)) indices.push_back(uint32_t(v.idx()));
  Animation result(std::move(indices), uint32_t(mesh.n_vertices()), std::move(positions),
                   {source.times().begin(), source.times().end()}, source.name());
  result.setCameraPath({source.cameraPath().begin(), source.cameraPath().end()});
  return result;
}

}  // namespace anim
