#include "anim/subdivide.hpp"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>
#include <algorithm>
#include <mutex>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include "tsah/base/error.hpp"

namespace anim {

namespace {

using Mesh = OpenMesh::TriMesh_ArrayKernelT<>;

// One side of a triangle: the undirected edge {low, high}, whether the triangle walks it from low
// to high, and the triangle.
struct TriangleSide {
  uint32_t low, high;
  bool forward;
  uint32_t triangle;
  auto order() const { return std::tie(low, high, triangle); }
};

// The first triangle (in index order) that breaks what a half-edge mesh needs: a repeated vertex,
// a third triangle on one edge (non-manifold) or a second triangle walking an edge in the same
// direction (inconsistently oriented); an empty string when there is none.
std::string firstTopologyProblem(std::span<const uint32_t> idx) {
  std::vector<TriangleSide> sides;
  sides.reserve(idx.size());
  for (std::size_t t = 0; t < idx.size(); t += 3) {
    const uint32_t triangle = uint32_t(t / 3);
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = idx[t + e], b = idx[t + (e + 1) % 3];
      if (a == b)
        return "triangle " + std::to_string(triangle) + " repeats vertex " + std::to_string(a);
      sides.push_back({std::min(a, b), std::max(a, b), a < b, triangle});
    }
  }
  std::sort(sides.begin(), sides.end(), [](const auto& x, const auto& y) { return x.order() < y.order(); });
  std::string problem;
  uint32_t culprit = UINT32_MAX;  // the offending triangle that comes first in the mesh
  for (std::size_t g = 0; g < sides.size();) {
    std::size_t end = g + 1;
    while (end < sides.size() && sides[end].low == sides[g].low && sides[end].high == sides[g].high) ++end;
    const std::string edge = "edge " + std::to_string(sides[g].low) + "-" + std::to_string(sides[g].high);
    if (end - g > 2 && sides[g + 2].triangle < culprit) {
      culprit = sides[g + 2].triangle;
      problem = edge + " is shared by more than two triangles (" + std::to_string(sides[g].triangle) + ", " +
                std::to_string(sides[g + 1].triangle) + ", " + std::to_string(culprit) + "): a non-manifold edge";
    } else if (end - g == 2 && sides[g].forward == sides[g + 1].forward && sides[g + 1].triangle < culprit) {
      culprit = sides[g + 1].triangle;
      problem = "triangle " + std::to_string(culprit) + " walks " + edge + " in the same direction as triangle " +
                std::to_string(sides[g].triangle) + ": the faces are not consistently oriented";
    }
    g = end;
  }
  return problem;
}

// OpenMesh's error stream is one for the process: it stays off while any subdivision links faces
// (subdivisions of a scene's sources run concurrently).
class SilencedOpenMeshErrors {
 public:
  SilencedOpenMeshErrors() {
    const std::lock_guard<std::mutex> lock(mutex());
    if (users()++ == 0) omerr().disable();
  }
  ~SilencedOpenMeshErrors() {
    const std::lock_guard<std::mutex> lock(mutex());
    if (--users() == 0) omerr().enable();
  }
  SilencedOpenMeshErrors(const SilencedOpenMeshErrors&) = delete;
  SilencedOpenMeshErrors& operator=(const SilencedOpenMeshErrors&) = delete;

 private:
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  static int& users() {
    static int n = 0;
    return n;
  }
};

}  // namespace

void checkSubdivisionTopology(const Animation& mesh) {
  if (const std::string problem = firstTopologyProblem(mesh.indices()); !problem.empty())
    throw tsah::DataError((mesh.name().empty() ? std::string("mesh") : mesh.name()) + ": cannot subdivide: " + problem);
}

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
  checkSubdivisionTopology(source);
  Mesh mesh;
  const std::vector<float> p = source.keyframe(0);
  std::vector<Mesh::VertexHandle> vh(source.vertexCount());
  for (uint32_t v = 0; v < source.vertexCount(); ++v) vh[v] = mesh.add_vertex(Mesh::Point(p[3 * v], p[3 * v + 1], p[3 * v + 2]));
  const auto idx = source.indices();
  // With manifold, consistently oriented edges, OpenMesh can still fail to link a triangle in at a
  // non-manifold vertex (two fans touching at one point, met in an unlucky order). Such a triangle
  // gets its own copies of its vertices and subdivides on its own. OpenMesh reports each such
  // face on its error stream; libraries never print, so that stream is off meanwhile (SilencedOpenMeshErrors).
  std::size_t rejected = 0;
  {
    const SilencedOpenMeshErrors silenced;
    for (std::size_t t = 0; t < idx.size(); t += 3) {
      if (mesh.add_face(vh[idx[t]], vh[idx[t + 1]], vh[idx[t + 2]]).is_valid()) continue;
      Mesh::VertexHandle own[3];
      for (int c = 0; c < 3; ++c) {
        // A copy, not mesh.point()'s reference: add_vertex grows the point array, which would free
        // the memory that reference points into before the new point is read from it.
        const Mesh::Point corner = mesh.point(vh[idx[t + c]]);
        own[c] = mesh.add_vertex(corner);
      }
      if (!mesh.add_face(own[0], own[1], own[2]).is_valid()) ++rejected;
    }
  }
  if (rejected > 0)
    throw tsah::Failure(who + ": cannot subdivide: OpenMesh could not link in " + std::to_string(rejected) +
                        " triangles");
  // LoopT leaves the new position of an isolated vertex unset (junk): a vertex no triangle uses (in
  // the input, or left behind by a triangle that got its own copies) is removed first.
  if (std::any_of(mesh.vertices().begin(), mesh.vertices().end(), [&](auto v) { return mesh.is_isolated(v); })) {
    mesh.request_vertex_status();
    mesh.request_edge_status();
    mesh.request_face_status();
    mesh.delete_isolated_vertices();
    mesh.garbage_collection();
  }
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
