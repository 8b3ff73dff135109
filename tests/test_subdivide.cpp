// Loop subdivision (anim/subdivide.hpp): closed meshes subdivide to finite, repeatable positions
// inside the input's box; meshes a half-edge mesh cannot hold are refused before OpenMesh sees
// them, through the C++ API and through a scene file. Run under ASan by the debug-asan preset.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"
#include "anim/load.hpp"
#include "anim/subdivide.hpp"
#include "test_support.hpp"

namespace fs = std::filesystem;

namespace {

// The unit tetrahedron, every face wound outwards.
const std::vector<float> kTetraPoints{0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
const std::vector<uint32_t> kTetraFaces{0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};

anim::Animation tetrahedron() { return anim::Animation(kTetraFaces, 4, kTetraPoints, {0.0}, "tetra"); }

// The unit cube (vertex x + 2y + 4z), every face wound outwards.
anim::Animation cube() {
  std::vector<float> p;
  for (int v = 0; v < 8; ++v) p.insert(p.end(), {float(v & 1), float(v >> 1 & 1), float(v >> 2 & 1)});
  const std::vector<uint32_t> faces{0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4,
                                    2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5};
  return anim::Animation(faces, 8, p, {0.0}, "cube");
}

// The tetrahedron with a triangle hanging off vertex 3: every edge is manifold and oriented, but
// vertex 3 is closed all around, so OpenMesh cannot link the extra triangle in there.
anim::Animation tetrahedronWithSpike() {
  std::vector<float> p = kTetraPoints;
  p.insert(p.end(), {0.5f, 0.5f, 2, -0.5f, 0.5f, 2});
  std::vector<uint32_t> faces = kTetraFaces;
  faces.insert(faces.end(), {3, 4, 5});
  return anim::Animation(faces, 6, p, {0.0}, "spike");
}

// Every level: 4x the triangles, finite coordinates inside the input's box (Loop's points are
// convex combinations of the input's), the same result twice.
void expectSafeSubdivision(const anim::Animation& mesh) {
  const anim::Bounds box = mesh.bounds();
  for (uint32_t levels : {1u, 2u, 3u}) {
    SCOPED_TRACE(mesh.name() + " level " + std::to_string(levels));
    const anim::Animation once = anim::subdivideLoop(mesh, levels);
    const anim::Animation again = anim::subdivideLoop(mesh, levels);
    EXPECT_EQ(once.triangleCount(), mesh.triangleCount() << (2 * levels));
    const std::vector<float> p = once.keyframe(0);
    EXPECT_EQ(p, again.keyframe(0));
    for (std::size_t i = 0; i < p.size(); ++i) {
      ASSERT_TRUE(std::isfinite(p[i])) << "coordinate " << i;
      EXPECT_GE(p[i], box.min[i % 3] - 1e-6f) << "coordinate " << i;
      EXPECT_LE(p[i], box.max[i % 3] + 1e-6f) << "coordinate " << i;
    }
  }
}

// The message of subdividing `mesh` once, or "" when it subdivides.
std::string subdivisionError(const anim::Animation& mesh) {
  try {
    anim::subdivideLoop(mesh, 1);
  } catch (const tsah::DataError& e) {
    return e.what();
  }
  return "";
}

anim::Animation tetrahedronWith(std::vector<uint32_t> faces, uint32_t vertices, const char* name) {
  std::vector<float> p = kTetraPoints;
  p.resize(3 * vertices, 0.5f);
  return anim::Animation(std::move(faces), vertices, p, {0.0}, name);
}

TEST(Subdivide, ClosedMeshesGiveFiniteRepeatablePointsInsideTheInput) {
  expectSafeSubdivision(tetrahedron());
  expectSafeSubdivision(cube());
}

TEST(Subdivide, ATriangleAtANonManifoldVertexSubdividesOnItsOwn) {
  expectSafeSubdivision(tetrahedronWithSpike());
}

TEST(Subdivide, VerticesNoTriangleUsesAreLeftOut) {
  std::vector<float> p = kTetraPoints;
  p.insert(p.end(), {0.25f, 0.25f, 0.25f});  // vertex 4: used by no triangle
  const anim::Animation unused(kTetraFaces, 5, p, {0.0}, "unused");
  expectSafeSubdivision(unused);
  EXPECT_EQ(anim::subdivideLoop(unused, 1).vertexCount(), 4u + 6u);  // V + E of the tetrahedron
}

TEST(Subdivide, NonManifoldEdgesFlippedFacesAndRepeatedVerticesAreRefused) {
  // Triangle 4 is a third one on edge 0-1.
  std::vector<uint32_t> nonManifold = kTetraFaces;
  nonManifold.insert(nonManifold.end(), {0, 1, 4});
  EXPECT_EQ(subdivisionError(tetrahedronWith(nonManifold, 5, "fin")),
            "fin: cannot subdivide: edge 0-1 is shared by more than two triangles (0, 1, 4): a non-manifold edge");
  // Triangle 3 wound inwards.
  std::vector<uint32_t> flipped = kTetraFaces;
  std::swap(flipped[10], flipped[11]);
  EXPECT_EQ(subdivisionError(tetrahedronWith(flipped, 4, "flipped")),
            "flipped: cannot subdivide: triangle 3 walks edge 1-2 in the same direction as triangle 0: the faces are "
            "not consistently oriented");
  EXPECT_EQ(subdivisionError(tetrahedronWith({0, 1, 2, 2, 1, 1}, 4, "repeat")),
            "repeat: cannot subdivide: triangle 1 repeats vertex 1");
}

TEST(Subdivide, AFlippedFaceInASceneFileIsRefusedNamingTheSceneAndTheObject) {
  const fs::path dir = tsah::test::scratchDir();
  tsah::test::writeText(dir / "flipped.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 4 3\n");
  tsah::test::writeText(dir / "s.json", R"({"objects": [{"name": "rock", "file": "flipped.obj", "subdivide": 2}]})");
  const std::string scene = (dir / "s.json").string();
  try {
    anim::load(scene);
    FAIL() << "loaded";
  } catch (const tsah::DataError& e) {
    const std::string message = e.what();
    EXPECT_EQ(message.rfind(scene + ": object 'rock': ", 0), 0u) << message;
    EXPECT_NE(message.find("triangle 3 walks edge 1-2 in the same direction as triangle 0: the faces are not "
                           "consistently oriented"),
              std::string::npos)
        << message;
    EXPECT_EQ(message.find('\n'), std::string::npos);
  }
}

}  // namespace
