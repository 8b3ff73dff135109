// Box views (tsah/box_view.hpp): which boxes are drawn, their geometry and colours, and the PLY and
// OBJ files, parsed back here.
#include <gtest/gtest.h>

#include <cstring>
#include <sstream>
#include <string>

#include "tsah/base/error.hpp"
#include "tsah/inspect/box_view.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/inspect/tree_quality.hpp"

namespace {

using tsah::Aabb;

// Four unit cubes in a row: a balanced tree of depth 2 (3 interior nodes, 4 leaves).
struct Row {
  std::vector<Aabb> prims{Aabb{{0, 0, 0}, {1, 1, 1}}, Aabb{{2, 0, 0}, {3, 1, 1}}, Aabb{{4, 0, 0}, {5, 1, 1}},
                          Aabb{{6, 0, 0}, {7, 1, 1}}};
  tsah::Bvh bvh = tsah::SweepSahBuilder().build(prims);
  tsah::FrameBoxes frame = tsah::frameBoxes(bvh, prims);
};

TEST(BoxView, DepthFilterAndLineGeometry) {
  Row r;
  tsah::BoxViewOptions o;
  o.style = tsah::BoxViewOptions::Style::Lines;
  tsah::BoxMesh all = tsah::buildBoxView(r.bvh, r.frame, {}, o);
  EXPECT_EQ(all.boxCount, 7u);
  EXPECT_EQ(all.lines.size(), 7u * 12 * 2);
  EXPECT_EQ(all.bands.size(), 7u * 8);
  EXPECT_TRUE(all.triangles.empty());
  // Every line is an edge of a unit cube or of the 3x1x1 / 7x1x1 boxes: axis-aligned, one axis changes.
  for (std::size_t l = 0; l < all.lines.size(); l += 2) {
    int changed = 0;
    for (int a = 0; a < 3; ++a) changed += all.positions[3 * all.lines[l] + a] != all.positions[3 * all.lines[l + 1] + a];
    EXPECT_EQ(changed, 1);
  }
  o.minDepth = o.maxDepth = 2;
  const tsah::BoxMesh leaves = tsah::buildBoxView(r.bvh, r.frame, {}, o);
  EXPECT_EQ(leaves.boxCount, 4u);
  EXPECT_EQ(leaves.minDepth, 2u);
  for (std::size_t v = 0; v < leaves.bands.size(); ++v) {  // only unit cubes: y and z in {0, 1}
    EXPECT_TRUE(leaves.positions[3 * v + 1] == 0.0f || leaves.positions[3 * v + 1] == 1.0f);
    EXPECT_EQ(leaves.bands[v], 0);  // one depth drawn: one band
  }
}

TEST(BoxView, CostShareFilterKeepsTheExpensiveNodes) {
  Row r;
  tsah::BoxViewOptions o;
  o.minCostShare = 0.2;  // root: 3*30 of 3*(30+14+14)+2*24 = 222 -> 40%; the two inner nodes 19% each
  const tsah::BoxMesh m = tsah::buildBoxView(r.bvh, r.frame, {}, o);
  EXPECT_EQ(m.boxCount, 1u);
  EXPECT_NEAR(r.frame.costShare[r.bvh.root], 90.0 / 222.0, 1e-12);
}

TEST(BoxView, BarsAreThinClosedBoxesAlongEveryEdge) {
  Row r;
  tsah::BoxViewOptions o;
  o.maxDepth = 0;
  o.barWidth = 0.1f;
  const tsah::BoxMesh m = tsah::buildBoxView(r.bvh, r.frame, {}, o);
  EXPECT_EQ(m.boxCount, 1u);
  EXPECT_EQ(m.triangles.size(), 12u * 12 * 3);  // 12 bars of 12 triangles
  // All bar corners lie within 0.05 of the root box's surface, outside by at most that.
  for (std::size_t v = 0; v < m.bands.size(); ++v) {
    const float x = m.positions[3 * v], y = m.positions[3 * v + 1], z = m.positions[3 * v + 2];
    EXPECT_GE(x, -0.05f - 1e-6f);
    EXPECT_LE(x, 7.05f + 1e-6f);
    EXPECT_GE(y, -0.05f - 1e-6f);
    EXPECT_LE(z, 1.05f + 1e-6f);
  }
}

TEST(BoxView, GrowthBandsAreLog2) {
  Row r;
  tsah::BoxViewOptions o;
  o.colour = tsah::BoxViewOptions::Colour::Growth;
  o.style = tsah::BoxViewOptions::Style::Lines;
  std::vector<double> growth(r.bvh.nodeCount(), 1.0);
  growth[r.bvh.root] = 5.0;  // band 2
  o.maxDepth = 0;
  const tsah::BoxMesh m = tsah::buildBoxView(r.bvh, r.frame, growth, o);
  EXPECT_EQ(m.bands.front(), 2);
  growth[r.bvh.root] = 1e9;
  EXPECT_EQ(tsah::buildBoxView(r.bvh, r.frame, growth, o).bands.front(), tsah::kBoxViewBands - 1);
  // The growth filter keeps the growing nodes only.
  o.maxDepth = 10;
  o.minGrowth = 3.0;
  growth[r.bvh.nodes[r.bvh.root].left] = 3.0;
  EXPECT_EQ(tsah::buildBoxView(r.bvh, r.frame, growth, o).boxCount, 2u);
  EXPECT_THROW(tsah::buildBoxView(r.bvh, r.frame, {}, o), tsah::ConfigError);
}

TEST(BoxView, PlyAndObjFilesParseBack) {
  Row r;
  tsah::BoxViewOptions o;
  o.style = tsah::BoxViewOptions::Style::Lines;
  tsah::BoxMesh m = tsah::buildBoxView(r.bvh, r.frame, {}, o);
  const std::vector<uint32_t> tri{0, 1, 2};
  const std::vector<float> pos{0, 0, 0, 1, 0, 0, 0, 1, 0};
  tsah::addMeshToBoxView(m, tri, pos);
  const std::size_t vertices = m.bands.size();

  const std::vector<uint8_t> ply = tsah::encodeBoxViewPly(m);
  const std::string text(ply.begin(), ply.end());
  const std::size_t end = text.find("end_header\n") + std::strlen("end_header\n");
  EXPECT_NE(text.find("element vertex " + std::to_string(vertices) + "\n"), std::string::npos);
  EXPECT_NE(text.find("element face 1\n"), std::string::npos);
  EXPECT_NE(text.find("element edge " + std::to_string(m.lines.size() / 2) + "\n"), std::string::npos);
  ASSERT_EQ(ply.size(), end + vertices * 15 + 13 + m.lines.size() * 4);
  // The last vertex is the mesh's (0, 1, 0) in grey; the face is 3 ids from the mesh's base.
  float y;
  std::memcpy(&y, &ply[end + (vertices - 1) * 15 + 4], 4);
  EXPECT_EQ(y, 1.0f);
  EXPECT_EQ(ply[end + (vertices - 1) * 15 + 12], tsah::boxViewColour(tsah::kBoxViewMeshBand)[0]);
  int32_t firstFaceVertex;
  std::memcpy(&firstFaceVertex, &ply[end + vertices * 15 + 1], 4);
  EXPECT_EQ(firstFaceVertex, int32_t(vertices - 3));

  const std::string obj = tsah::encodeBoxViewObj(m, "view.mtl");
  std::istringstream in(obj);
  std::string line, material;
  std::size_t v = 0, l = 0, f = 0;
  while (std::getline(in, line)) {
    if (line.rfind("v ", 0) == 0) ++v;
    if (line.rfind("l ", 0) == 0) ++l;
    if (line.rfind("f ", 0) == 0) {
      ++f;
      EXPECT_EQ(material, "mesh");
    }
    if (line.rfind("usemtl ", 0) == 0) material = line.substr(7);
  }
  EXPECT_EQ(v, vertices);
  EXPECT_EQ(l, m.lines.size() / 2);
  EXPECT_EQ(f, 1u);
  EXPECT_NE(obj.find("mtllib view.mtl\n"), std::string::npos);
  const std::string mtl = tsah::encodeBoxViewMtl();
  EXPECT_NE(mtl.find("newmtl band7\nKd 0.863 0.118 0.118\n"), std::string::npos);
  EXPECT_NE(mtl.find("newmtl mesh\n"), std::string::npos);
}

}  // namespace
