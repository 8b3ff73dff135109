#include "tsah/inspect/box_view.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

// Blue -> cyan -> green -> yellow -> red; then the mesh grey.
constexpr std::array<std::array<uint8_t, 3>, kBoxViewBands + 1> kPalette{{{40, 60, 220},
                                                                          {30, 140, 230},
                                                                          {20, 190, 190},
                                                                          {40, 190, 80},
                                                                          {160, 210, 40},
                                                                          {240, 200, 30},
                                                                          {245, 120, 30},
                                                                          {220, 30, 30},
                                                                          {170, 170, 170}}};

uint32_t addVertex(BoxMesh& m, float x, float y, float z, uint8_t band) {
  m.positions.insert(m.positions.end(), {x, y, z});
  m.bands.push_back(band);
  return uint32_t(m.bands.size() - 1);
}

// The 8 corners of [lo, hi] (bit 0: x, bit 1: y, bit 2: z picks hi).
std::array<uint32_t, 8> addCorners(BoxMesh& m, const Vec3& lo, const Vec3& hi, uint8_t band) {
  std::array<uint32_t, 8> v;
  for (int c = 0; c < 8; ++c)
    v[c] = addVertex(m, c & 1 ? hi.x : lo.x, c & 2 ? hi.y : lo.y, c & 4 ? hi.z : lo.z, band);
  return v;
}

// A closed box of 12 outward-facing triangles.
void addSolidBox(BoxMesh& m, const Vec3& lo, const Vec3& hi, uint8_t band) {
  const auto v = addCorners(m, lo, hi, band);
  static constexpr uint8_t kQuads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : kQuads)
    m.triangles.insert(m.triangles.end(), {v[q[0]], v[q[1]], v[q[2]], v[q[0]], v[q[2]], v[q[3]]});
}

// The 12 edges of a box as index pairs of corners (corners differing in one bit).
constexpr uint8_t kEdges[12][2] = {{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3},
                                   {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};

Vec3 corner(const Aabb& b, int c) { return {c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z}; }

void addBox(BoxMesh& m, const Aabb& b, uint8_t band, const BoxViewOptions& o, float halfWidth) {
  if (o.style == BoxViewOptions::Style::Lines) {
    const auto v = addCorners(m, b.lo, b.hi, band);
    for (const auto& e : kEdges) m.lines.insert(m.lines.end(), {v[e[0]], v[e[1]]});
    return;
  }
  const Vec3 h{halfWidth, halfWidth, halfWidth};
  for (const auto& e : kEdges) {  // every edge is an axis-aligned segment: its bar is a thin box
    const Vec3 p = corner(b, e[0]), q = corner(b, e[1]);
    addSolidBox(m, vmin(p, q) - h, vmax(p, q) + h, band);
  }
}

uint8_t band(double x, double lo, double hi) {
  if (!(hi > lo)) return 0;
  return uint8_t(std::clamp(int(std::floor((x - lo) / (hi - lo + 1.0) * kBoxViewBands)), 0, int(kBoxViewBands - 1)));
}

template <typename T>
void put(std::vector<uint8_t>& out, const T& value) {
  const auto* p = reinterpret_cast<const uint8_t*>(&value);
  out.insert(out.end(), p, p + sizeof(T));
}

}  // namespace

std::array<uint8_t, 3> boxViewColour(uint32_t b) { return kPalette[std::min(b, kBoxViewBands)]; }

BoxMesh buildBoxView(const Bvh& bvh, const FrameBoxes& frame, std::span<const double> nodeGrowth,
                     const BoxViewOptions& o) {
  BoxMesh m;
  if (bvh.nodes.empty()) return m;
  if ((o.colour == BoxViewOptions::Colour::Growth || o.minGrowth > 0.0) && nodeGrowth.size() != bvh.nodes.size())
    throw tsah::ConfigError("buildBoxView: growth colours or filters need one growth value per node");
  const std::vector<uint32_t> depth = nodeDepths(bvh);
  std::vector<uint32_t> chosen;
  for (uint32_t i = 0; i < bvh.nodeCount(); ++i)
    if (depth[i] != kInvalidIndex && depth[i] >= o.minDepth && depth[i] <= o.maxDepth &&
        frame.costShare[i] >= o.minCostShare && (o.minGrowth <= 0.0 || nodeGrowth[i] >= o.minGrowth) &&
        !frame.boxes[i].empty())
      chosen.push_back(i);
  if (chosen.empty()) return m;
  m.minDepth = depth[chosen.front()];
  for (uint32_t i : chosen) {
    m.minDepth = std::min(m.minDepth, depth[i]);
    m.maxDepth = std::max(m.maxDepth, depth[i]);
  }
  const Vec3 diagonal = frame.boxes[bvh.root].extent();
  const float halfWidth = 0.5f * (o.barWidth > 0.0f ? o.barWidth
                                                    : 1e-3f * std::sqrt(diagonal.x * diagonal.x + diagonal.y * diagonal.y +
                                                                        diagonal.z * diagonal.z));
  for (uint32_t i : chosen) {
    const uint8_t b = o.colour == BoxViewOptions::Colour::Depth
                          ? band(depth[i], m.minDepth, m.maxDepth)
                          : uint8_t(std::clamp(int(std::floor(std::log2(std::max(nodeGrowth[i], 1.0)))), 0,
                                               int(kBoxViewBands - 1)));
    addBox(m, frame.boxes[i], b, o, halfWidth);
    ++m.boxCount;
  }
  return m;
}

void addMeshToBoxView(BoxMesh& m, std::span<const uint32_t> indices, std::span<const float> positions) {
  const uint32_t base = uint32_t(m.bands.size());
  for (std::size_t v = 0; v + 2 < positions.size(); v += 3)
    addVertex(m, positions[v], positions[v + 1], positions[v + 2], uint8_t(kBoxViewMeshBand));
  for (uint32_t i : indices) m.triangles.push_back(base + i);
}

std::vector<uint8_t> encodeBoxViewPly(const BoxMesh& m) {
  const std::size_t vertices = m.bands.size(), faces = m.triangles.size() / 3, edges = m.lines.size() / 2;
  std::string header = "ply\nformat binary_little_endian 1.0\ncomment tsah export --boxes\n";
  header += "element vertex " + std::to_string(vertices) +
            "\nproperty float x\nproperty float y\nproperty float z\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  header += "element face " + std::to_string(faces) + "\nproperty list uchar int vertex_indices\n";
  if (edges) header += "element edge " + std::to_string(edges) + "\nproperty int vertex1\nproperty int vertex2\n";
  header += "end_header\n";
  std::vector<uint8_t> out(header.begin(), header.end());
  out.reserve(out.size() + vertices * 15 + faces * 13 + edges * 8);
  for (std::size_t v = 0; v < vertices; ++v) {
    for (int a = 0; a < 3; ++a) put(out, m.positions[3 * v + a]);
    const auto rgb = boxViewColour(m.bands[v]);
    out.insert(out.end(), rgb.begin(), rgb.end());
  }
  for (std::size_t f = 0; f < faces; ++f) {
    out.push_back(3);
    for (int c = 0; c < 3; ++c) put(out, int32_t(m.triangles[3 * f + c]));
  }
  for (std::size_t e = 0; e < edges; ++e)
    for (int c = 0; c < 2; ++c) put(out, int32_t(m.lines[2 * e + c]));
  return out;
}

std::string encodeBoxViewMtl() {
  std::string mtl = "# tsah export --boxes: band0 (blue) .. band7 (red), mesh (grey)\n";
  char line[96];
  for (uint32_t b = 0; b <= kBoxViewBands; ++b) {
    const auto c = boxViewColour(b);
    const std::string name = b == kBoxViewMeshBand ? "mesh" : "band" + std::to_string(b);
    std::snprintf(line, sizeof line, "newmtl %s\nKd %.3f %.3f %.3f\n", name.c_str(), c[0] / 255.0, c[1] / 255.0,
                  c[2] / 255.0);
    mtl += line;
  }
  return mtl;
}

std::string encodeBoxViewObj(const BoxMesh& m, const std::string& mtlName) {
  std::string obj = "# tsah export --boxes\nmtllib " + mtlName + "\n";
  char line[128];
  for (std::size_t v = 0; v < m.bands.size(); ++v) {
    std::snprintf(line, sizeof line, "v %.7g %.7g %.7g\n", double(m.positions[3 * v]), double(m.positions[3 * v + 1]),
                  double(m.positions[3 * v + 2]));
    obj += line;
  }
  // Elements grouped by the band of their first vertex, one usemtl per band.
  for (uint32_t b = 0; b <= kBoxViewBands; ++b) {
    std::string body;
    for (std::size_t t = 0; t + 2 < m.triangles.size(); t += 3)
      if (m.bands[m.triangles[t]] == b) {
        std::snprintf(line, sizeof line, "f %u %u %u\n", m.triangles[t] + 1, m.triangles[t + 1] + 1, m.triangles[t + 2] + 1);
        body += line;
      }
    for (std::size_t l = 0; l + 1 < m.lines.size(); l += 2)
      if (m.bands[m.lines[l]] == b) {
        std::snprintf(line, sizeof line, "l %u %u\n", m.lines[l] + 1, m.lines[l + 1] + 1);
        body += line;
      }
    if (body.empty()) continue;
    obj += b == kBoxViewMeshBand ? std::string("usemtl mesh\n") : "usemtl band" + std::to_string(b) + "\n";
    obj += body;
  }
  return obj;
}

}  // namespace tsah
