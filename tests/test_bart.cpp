// BART AFF importer: every command on small hand-written scenes, the splines against hand-computed
// values, includes, errors with file:line, randomized mutations, and the real BART scenes when the
// data folder is present.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "anim/bart.hpp"
#include "tsah/base/error.hpp"
#include "anim/load.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;

using tsah::test::throwsFileError;
using tsah::test::writeText;

struct Loaded {
  anim::Animation animation;
  std::vector<std::string> warnings;
};

Loaded loadText(const std::string& text, anim::BartOptions options = {}, const std::string& name = "scene.aff") {
  const fs::path file = tsah::test::scratchDir() / name;
  writeText(file, text);
  std::vector<std::string> warnings;
  options.warning = [&](const std::string& w) { warnings.push_back(w); };
  anim::Animation a = anim::importBart(file.string(), options);
  return {std::move(a), warnings};
}

// The message of the ImportError that loading `text` throws ("" when it loads).
std::string errorOf(const std::string& text, const std::string& name = "scene.aff") {
  try {
    loadText(text, {}, name);
  } catch (const tsah::FileError& e) {
    return e.what();
  }
  return {};
}

std::array<float, 3> vertex(const anim::Animation& a, uint32_t k, uint32_t v) {
  const auto p = a.keyframe(k);
  return {p[3 * v], p[3 * v + 1], p[3 * v + 2]};
}

// Vertex v of keyframe k is `expected`, each coordinate within `tolerance`.
void expectVertexNear(const anim::Animation& a, uint32_t k, uint32_t v, std::array<float, 3> expected,
                      float tolerance) {
  const auto p = vertex(a, k, v);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(p[i], expected[i], tolerance) << "keyframe " << k << " vertex " << v << " coordinate " << i;
}

// "f7.aff" (built with += because GCC 12 warns falsely about "f" + std::to_string(7)).
std::string numberedFile(const char* prefix, int n) {
  std::string s(prefix);
  s += std::to_string(n);
  s += ".aff";
  return s;
}

const char* kTriangle = "p 3\n1 0 0\n0 1 0\n0 0 1\n";

// ---- geometry commands ----------------------------------------------------------------------------

TEST(Bart, IndexedMeshKeepsOnlyUsedVerticesAndSkipsNormalsAndTextures) {
  const auto [a, warnings] = loadText(
      "m\nvertices 5\n0 0 0\n1 0 0\n9 9 9\n1 1 0\n0 1 0\n"
      "normals 1\n0 0 1\n"
      "texturecoords 2 wood.ppm\n0 0\n1 1\n"
      "triangles 2\n0 1 3  0 0 0  0 1 1\n0 3 4  0 0 0  0 1 0\n");
  EXPECT_EQ(a.triangleCount(), 2u);
  EXPECT_EQ(a.vertexCount(), 4u);  // vertex 2 (9 9 9) is unused
  EXPECT_EQ(a.keyframeCount(), 1u);
  EXPECT_EQ(a.bounds().max[0], 1.0f);
  const std::vector<uint32_t> idx(a.indices().begin(), a.indices().end());
  EXPECT_EQ(idx, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
  EXPECT_EQ(vertex(a, 0, 2), (std::array<float, 3>{1, 1, 0}));
  ASSERT_EQ(warnings.size(), 1u);  // the one summary of skipped things
  EXPECT_NE(warnings[0].find("1 texture reference"), std::string::npos) << warnings[0];
}

TEST(Bart, MeshWithoutNormalsOrTexturesReadsThreeIndicesPerTriangle) {
  const auto a = loadText("m vertices 3 0 0 0 1 0 0 0 1 0 triangles 1 0 1 2").animation;
  EXPECT_EQ(a.triangleCount(), 1u);
  EXPECT_EQ(a.vertexCount(), 3u);
}

TEST(Bart, PolygonsAreFannedAndPatchesSkipTheirNormals) {
  const auto a = loadText(
                     "p 5\n0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 1 0\n"
                     "pp 4\n0 0 1 0 0 1\n1 0 1 0 0 1\n1 1 1 0 0 1\n0 1 1 0 0 1\n")
                     .animation;
  EXPECT_EQ(a.triangleCount(), 3u + 2u);
  EXPECT_EQ(a.vertexCount(), 9u);
  const std::vector<uint32_t> idx(a.indices().begin(), a.indices().end());
  EXPECT_EQ(std::vector<uint32_t>(idx.begin(), idx.begin() + 9), (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 3, 4}));
  EXPECT_EQ(vertex(a, 0, 7), (std::array<float, 3>{1, 1, 1}));
}

TEST(Bart, TexturedTrianglesKeepPositionsOnly) {
  const auto a = loadText(
                     "tt wall.ppm\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n"
                     "ttp wall.ppm\n0 0 2 0 0 1 0 0\n1 0 2 0 0 1 1 0\n0 1 2 0 0 1 0 1\n")
                     .animation;
  EXPECT_EQ(a.triangleCount(), 2u);
  EXPECT_EQ(vertex(a, 0, 4), (std::array<float, 3>{1, 0, 2}));
}

TEST(Bart, CylindersConesAndSpheresAreTessellatedOnTheirSurface) {
  anim::BartOptions options;
  options.tessellation = 8;
  const auto a = loadText(
                     "c 0 0 0 1  0 2 0 1\n"       // cylinder of radius 1 along y
                     "c 5 0 0 -0.5  5 0 3 0\n"  // cone (negative radius: inside visible), apex radius 0
                     "s 0 10 0 2\n",
                     options)
                     .animation;
  const uint32_t cylinder = 2 * 8, cone = 8, sphere = 2 * 8 * (4 - 1);
  ASSERT_EQ(a.triangleCount(), cylinder + cone + sphere);
  const uint32_t cylinderVerts = 16, coneVerts = 9;
  for (uint32_t v = 0; v < a.vertexCount(); ++v) {
    const auto p = vertex(a, 0, v);
    if (v < cylinderVerts) {
      EXPECT_NEAR(std::hypot(p[0], p[2]), 1.0, 1e-5);
      EXPECT_TRUE(p[1] == 0.0f || std::fabs(p[1] - 2.0f) < 1e-6f);
    } else if (v < cylinderVerts + coneVerts) {
      // Distance from the axis shrinks linearly from 0.5 at z=0 to 0 at the apex z=3.
      EXPECT_NEAR(std::hypot(p[0] - 5.0, p[1]), 0.5 * (1.0 - p[2] / 3.0), 1e-5);
    } else {
      EXPECT_NEAR(std::sqrt(p[0] * p[0] + (p[1] - 10.0) * (p[1] - 10.0) + p[2] * p[2]), 2.0, 1e-5);
    }
  }
  EXPECT_EQ(a.degenerateTriangleCount(), 0u);
}

TEST(Bart, StaticTransformsApplyScaleThenRotationThenTranslationAndNest) {
  const auto a = loadText(
                     "xs 2 2 2  0 0 1 90  1 1 1 {\n"
                     "  p 3\n1 0 0\n0 1 0\n0 0 1\n"
                     "  xs 1 1 1  1 0 0 0  0 0 5 { p 3\n1 0 0\n0 1 0\n0 0 1\n }\n"
                     "}\n")
                     .animation;
  // (1,0,0): scaled (2,0,0), rotated 90 degrees about z (0,2,0), translated (1,3,1).
  expectVertexNear(a, 0, 0, {1, 3, 1}, 1e-6f);
  // The inner block first moves by (0,0,5), then by the outer transform: (1,3,11).
  expectVertexNear(a, 0, 3, {1, 3, 11}, 1e-6f);
}

// ---- animation ------------------------------------------------------------------------------------

TEST(Bart, AnimatedTransformFollowsItsTranslationSplineAtTheFrameTimes) {
  // Keys x = -2, 0, 1, 3 at t = -1, 0, 1, 3 (TCB at key 1: 0.5, 0.2, -0.4); frames at 0, .25, ..., 1.
  const auto a = loadText(std::string("a 0 1 5\nx mover { ") + kTriangle +
                          "}\n"
                          "k mover {\n transl 4\n -1 -2 0 0 0 0 0\n 0 0 0 0 0.5 0.2 -0.4\n 1 1 0 0 0 0 0\n 3 3 0 0 0 0 0\n}\n")
                     .animation;
  ASSERT_EQ(a.keyframeCount(), 5u);
  EXPECT_DOUBLE_EQ(a.times()[1], 0.25);
  // Hermite segment from 0 to 1: c1 = 0.64, c2 = 0.72, c3 = -0.36 (see the PositionSpline test).
  const double expected[5] = {0.0, 0.199375, 0.455, 0.64 * 0.75 + 0.72 * 0.5625 - 0.36 * 0.421875, 1.0};
  for (uint32_t k = 0; k < 5; ++k) EXPECT_NEAR(vertex(a, k, 0)[0], 1.0 + expected[k], 1e-6) << "frame " << k;
}

TEST(Bart, PositionSplineMatchesHandComputedKochanekBartelsValues) {
  // Segment between keys 1 and 2: adj0 = 2(1-0)/(1+1) = 1, adj1 = 2(1-0)/(3-0) = 2/3.
  // out0 = .5*1*(1-.5)(1+.2)(1-.4) = .18, out1 = .5*1*(1-.5)(1-.2)(1+.4) = .28,
  // Tout = .28*(1-0) + .18*(0-(-2)) = .64; in0 = in1 = 1/3, Tin = (3-1)/3 + 1/3 = 1;
  // c2 = 3 - 2*.64 - 1 = .72, c3 = -2 + .64 + 1 = -.36.
  std::vector<anim::bart::SplineKey> keys{{-1, {-2, 10, 0}, 0, 0, 0},
                                          {0, {0, 10, 0}, 0.5, 0.2, -0.4},
                                          {1, {1, 10, 0}, 0, 0, 0},
                                          {3, {3, 10, 0}, 0, 0, 0}};
  const anim::bart::PositionSpline s(keys);
  EXPECT_NEAR(s.at(0.5)[0], 0.32 + 0.18 - 0.045, 1e-12);
  EXPECT_NEAR(s.at(0.25)[0], 0.16 + 0.045 - 0.005625, 1e-12);
  EXPECT_NEAR(s.at(0.5)[1], 10.0, 1e-12);  // constant stays constant
  EXPECT_EQ(s.at(-7)[0], 0.0);             // clamped to key 1 before it
  EXPECT_EQ(s.at(2.5)[0], 1.0);            // and to key n-2 after it
  EXPECT_EQ(s.startTime(), 0.0);
  EXPECT_EQ(s.endTime(), 1.0);
  EXPECT_THROW(anim::bart::PositionSpline(std::vector<anim::bart::SplineKey>(3)), tsah::Error);
}

double angleAboutZ(const anim::bart::Quaternion& q) {
  const auto r = anim::bart::rotationMatrix(q);
  EXPECT_NEAR(r[8], 1.0, 1e-9);  // still a rotation about z
  return std::atan2(r[3], r[0]) * 180.0 / kPi;
}

anim::bart::RotationSpline zSpline(std::vector<double> degrees, std::vector<double> times) {
  std::vector<anim::bart::RotationKey> keys;
  for (std::size_t i = 0; i < degrees.size(); ++i) keys.push_back({times[i], {0, 0, 1}, degrees[i], 0, 0, 0});
  return anim::bart::RotationSpline(keys);
}

TEST(Bart, RotationSplineUniformTurnInterpolatesTheAngle) {
  // Equal steps: the tangents equal the step, squad's inner quaternions equal the keys: slerp.
  const auto s = zSpline({0, 90, 180, 270}, {-1, 0, 1, 2});
  EXPECT_NEAR(angleAboutZ(s.at(0.5)), 135.0, 1e-9);
  EXPECT_NEAR(angleAboutZ(s.at(0.0)), 90.0, 1e-9);
  EXPECT_NEAR(std::fabs(angleAboutZ(s.at(5.0))), 180.0, 1e-9);
}

TEST(Bart, RotationSplineEasesInAndOutAsSquadPrescribes) {
  // Keys 0, 0, 90, 90 degrees: half angles p = 0, q = 45, a = -11.25, b = 56.25 (degrees).
  // At u = .25: slerp(p,q) = 11.25, slerp(a,b) = 5.625, h = 2u(1-u) = .375: 11.25 - .375 * 5.625
  // = 9.140625 half angle, 18.28125 degrees.
  const auto s = zSpline({0, 0, 90, 90}, {-1, 0, 1, 2});
  EXPECT_NEAR(angleAboutZ(s.at(0.25)), 18.28125, 1e-9);
  EXPECT_NEAR(angleAboutZ(s.at(0.5)), 45.0, 1e-9);
  EXPECT_NEAR(angleAboutZ(s.at(0.75)), 90.0 - 18.28125, 1e-9);
}

TEST(Bart, RotationSplineFlipsAKeyToTakeTheShortWay) {
  // 340 degrees is -20: the spline turns 20 degrees clockwise, not 340 counter-clockwise.
  const auto s = zSpline({0, 0, 340, 340}, {-1, 0, 1, 2});
  EXPECT_NEAR(angleAboutZ(s.at(0.5)), -10.0, 1e-9);
}

TEST(Bart, RotationSplineKeepsTheReferenceTreatmentOfTheOuterKey) {
  // The last key (200 degrees) is never sign-adjusted by the BART reference: its tangent takes the
  // long way, half angle +50 degrees, so b = exp(-25 deg) and the turn at u = .5 is -12.5 degrees.
  const auto s = zSpline({0, 0, 0, 200}, {-1, 0, 1, 2});
  EXPECT_NEAR(angleAboutZ(s.at(0.5)), -12.5, 1e-9);
}

TEST(Bart, AnimatedTransformComposesTranslationRotationAndScale) {
  const auto a = loadText(std::string("a 0 1 3\nx spin { ") + kTriangle +
                          "}\n"
                          "k spin {\n"
                          " rot 4\n -1 0 0 1 -90 0 0 0\n 0 0 0 1 0 0 0 0\n 1 0 0 1 90 0 0 0\n 2 0 0 1 180 0 0 0\n"
                          " scale 4\n -1 2 2 2 0 0 0\n 0 2 2 2 0 0 0\n 1 2 2 2 0 0 0\n 2 2 2 2 0 0 0\n"
                          " transl 4\n -1 0 0 7 0 0 0\n 0 0 0 7 0 0 0\n 1 0 0 7 0 0 0\n 2 0 0 7 0 0 0\n"
                          "}\n")
                     .animation;
  // t = .5: uniform turn, 45 degrees. (1,0,0) -> scale (2,0,0) -> rotate (sqrt2,sqrt2,0) -> translate.
  expectVertexNear(a, 1, 0, {std::sqrt(2.0f), std::sqrt(2.0f), 7}, 1e-5f);
}

TEST(Bart, NestedAnimatedTransformsComposeParentFirst) {
  const auto a = loadText(std::string("a 0 1 2\nx outer { xs 1 1 1 0 0 1 0 0 1 0 { x inner { ") + kTriangle +
                          "} } }\n"
                          "k outer { transl 4 -1 0 0 0 0 0 0  0 0 0 0 0 0 0  1 10 0 0 0 0 0  2 20 0 0 0 0 0 }\n"
                          "k inner { rot 4 -1 0 0 1 0 0 0 0  0 0 0 1 0 0 0 0  1 0 0 1 90 0 0 0  2 0 0 1 180 0 0 0 }\n")
                     .animation;
  // t = 1: inner turns (1,0,0) to (0,1,0); xs lifts it to (0,2,0); outer moves it to (10,2,0).
  expectVertexNear(a, 1, 0, {10, 2, 0}, 1e-5f);
}

TEST(Bart, AnimatedTrianglesBlendTheirKeyShapesAndClamp) {
  const auto a = loadText(
                     "a -1 2 4\n"
                     "tpa 2\n 0\n 0 0 0 0 0 1\n 1 0 0 0 0 1\n 0 1 0 0 0 1\n"
                     " 1\n 0 0 2 0 0 1\n 3 0 0 0 0 1\n 0 1 2 0 0 1\n")
                     .animation;
  ASSERT_EQ(a.keyframeCount(), 4u);  // t = -1, 0, 1, 2
  EXPECT_EQ(vertex(a, 0, 1)[0], 1.0f);  // before the first key shape
  EXPECT_EQ(vertex(a, 1, 1)[0], 1.0f);
  EXPECT_EQ(vertex(a, 2, 1)[0], 3.0f);
  EXPECT_EQ(vertex(a, 3, 1)[0], 3.0f);  // after the last
  const auto mid = loadText("a 0 1 3\ntpa 2 0 0 0 0 0 0 1 1 0 0 0 0 1 0 1 0 0 0 1  1 0 0 2 0 0 1 3 0 0 0 0 1 0 1 2 0 0 1")
                       .animation;
  EXPECT_FLOAT_EQ(vertex(mid, 1, 0)[2], 1.0f);
  EXPECT_FLOAT_EQ(vertex(mid, 1, 1)[0], 2.0f);
}

TEST(Bart, VisibilityKeysCollapseHiddenObjects) {
  const auto a = loadText(std::string("a 0 2 3\nx blink { ") + kTriangle + "}\nk blink { visibility 2 0.5 0 1.5 1 }\n")
                     .animation;
  const auto at = [&](uint32_t k) { return vertex(a, k, 0)[0] - vertex(a, k, 1)[0]; };
  EXPECT_NE(at(0), 0.0f);  // t = 0: visible
  EXPECT_EQ(at(1), 0.0f);  // t = 1: hidden, all vertices on one point
  EXPECT_NE(at(2), 0.0f);  // t = 2: visible again
}

TEST(Bart, FrameRangeAndFpsOverride) {
  const std::string scene = std::string("a 0 2 5\n") + kTriangle;
  const auto native = loadText(scene).animation;
  ASSERT_EQ(native.keyframeCount(), 5u);
  EXPECT_DOUBLE_EQ(native.times()[3], 1.5);
  anim::BartOptions options;
  options.fps = 3;
  const auto resampled = loadText(scene, options).animation;
  ASSERT_EQ(resampled.keyframeCount(), 7u);
  EXPECT_DOUBLE_EQ(resampled.times()[6], 2.0);
  EXPECT_NEAR(resampled.times()[1], 1.0 / 3.0, 1e-15);
}

TEST(Bart, SceneWithoutRangeSamplesTheAnimatedSpanAndSaysSo) {
  const auto [a, warnings] = loadText(std::string("x m { ") + kTriangle +
                                      "}\nk m { transl 4 0 0 0 0 0 0 0  0 0 0 0 0 0 0  2 1 0 0 0 0 0  3 1 0 0 0 0 0 }\n");
  EXPECT_EQ(a.keyframeCount(), 51u);  // [0, 2] at 25 frames per time unit
  EXPECT_EQ(a.endTime(), 2.0);
  ASSERT_FALSE(warnings.empty());
  EXPECT_NE(warnings[0].find("no 'a' line"), std::string::npos);
}

TEST(Bart, CameraPathFollowsTheCameraKeys) {
  const auto a = loadText(std::string("v from 0 0 5 at 0 0 0 up 0 1 0 angle 30 hither 1 resolution 64 48\n") + kTriangle +
                          "a 0 1 3\n"
                          "k camera {\n transl 4 -1 0 0 5 0 0 0  0 0 0 5 0 0 0  1 4 0 5 0 0 0  2 8 0 5 0 0 0\n"
                          " rot 4 -1 0 1 0 0 0 0 0  0 0 1 0 0 0 0 0  1 0 1 0 90 0 0 0  2 0 1 0 180 0 0 0 }\n")
                     .animation;
  const auto cam = a.cameraPath();
  ASSERT_EQ(cam.size(), 3u);
  EXPECT_FLOAT_EQ(cam[0].fovyDegrees, 30.0f);
  // t = 0: no turn, looks down -z from (0,0,5) as far as the view's at point.
  EXPECT_NEAR(cam[0].lookAt[2], 0.0f, 1e-6f);
  EXPECT_NEAR(cam[0].up[1], 1.0f, 1e-6f);
  // t = 1: at (4,0,5), turned 90 degrees about y: looking down -x.
  EXPECT_NEAR(cam[2].eye[0], 4.0f, 1e-6f);
  EXPECT_NEAR(cam[2].lookAt[0], -1.0f, 1e-5f);
  EXPECT_NEAR(cam[2].lookAt[2], 5.0f, 1e-5f);
}

TEST(Bart, StaticViewGivesOneCameraKey) {
  const auto a = loadText(std::string("v\nfrom 1 2 3\nat 1 2 0\nup 0 1 0\nangle 45\nhither 0.1\nresolution 8 8\n") + kTriangle)
                     .animation;
  ASSERT_EQ(a.cameraPath().size(), 1u);
  EXPECT_EQ(a.cameraPath()[0].eye[2], 3.0f);
  EXPECT_EQ(a.cameraPath()[0].lookAt[2], 0.0f);
}

TEST(Bart, SkippedThingsAreSummarisedInOneWarningAndUnkeyedTransformsNamed) {
  const auto [a, warnings] = loadText(std::string("b 0 0 0\nam 1 1 1\nl 1 1 1\nl 1 2 3 1 1 1\nla sun 1 1 1 0.5 0.5 0.5\n"
                                                  "f 1 1 1 1 1 1 1 1\nfm 1 1 1 1 1 1 1 1 1 1 1 1\nx lonely { ") +
                                      kTriangle + "}\n");
  EXPECT_EQ(a.triangleCount(), 1u);
  ASSERT_EQ(warnings.size(), 2u);
  EXPECT_NE(warnings[0].find("'lonely' has no 'k' block"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("scene.aff: line 8"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[1].find("2 materials, 4 lights"), std::string::npos) << warnings[1];
}

TEST(Bart, CommentsAndGluedBracesAreAccepted) {
  const auto a = loadText("# header\n% other comment style\nxs 1 1 1 0 0 1 0 0 0 0{p 3 % inline\n0 0 0 1 0 0 0 1 0}\n")
                     .animation;
  EXPECT_EQ(a.triangleCount(), 1u);
}

// ---- includes -------------------------------------------------------------------------------------

TEST(Bart, IncludesResolveAgainstTheIncludingFileAndShareParsedFiles) {
  const fs::path dir = tsah::test::scratchDir();
  writeText(dir / "parts" / "tri.aff", kTriangle);
  writeText(dir / "parts" / "pair.aff", "i 0 tri.aff\nxs 1 1 1 0 0 1 0 5 0 0 { i 0 tri.aff }\n");
  writeText(dir / "main.aff", "i 0 parts/pair.aff\nxs 1 1 1 0 0 1 0 0 5 0 { i 0 parts/pair.aff }\ni 1 parts/tri.aff\n");
  const auto a = anim::importBart((dir / "main.aff").string());
  EXPECT_EQ(a.triangleCount(), 4u);  // the detail-1 include is skipped at the default detail 0
  EXPECT_EQ(a.bounds().max[0], 6.0f);
  EXPECT_EQ(a.bounds().max[1], 6.0f);
  writeText(dir / "detailed.aff", "d 1\ni 1 parts/tri.aff\n");
  EXPECT_EQ(anim::importBart((dir / "detailed.aff").string()).triangleCount(), 1u);
}

TEST(Bart, IncludeCyclesAreErrorsNamingTheChain) {
  const fs::path dir = tsah::test::scratchDir();
  writeText(dir / "a.aff", std::string(kTriangle) + "i 0 b.aff\n");
  writeText(dir / "b.aff", "\ni 0 a.aff\n");
  EXPECT_TRUE(throwsFileError([&] { anim::importBart((dir / "a.aff").string()); },
                              {"b.aff: line 2: include cycle: a.aff -> b.aff -> a.aff"}));
  writeText(dir / "self.aff", "i 0 ./self.aff\n");
  EXPECT_THROW(anim::importBart((dir / "self.aff").string()), tsah::FileError);
}

TEST(Bart, IncludeDepthIsBounded) {
  const fs::path dir = tsah::test::scratchDir();
  for (int i = 0; i < 40; ++i) writeText(dir / numberedFile("f", i), "i 0 " + numberedFile("f", i + 1) + "\n");
  writeText(dir / "f40.aff", kTriangle);
  EXPECT_TRUE(throwsFileError([&] { anim::importBart((dir / "f0.aff").string()); }, {"nested deeper than 32"}));
  anim::BartOptions deep;
  deep.maxIncludeDepth = 64;
  EXPECT_EQ(anim::importBart((dir / "f0.aff").string(), deep).triangleCount(), 1u);
}

TEST(Bart, ExponentialIncludeFanOutIsRefusedBeforeExpanding) {
  const fs::path dir = tsah::test::scratchDir();
  writeText(dir / "l0.aff", kTriangle);
  const std::string tenTimes = [] {
    std::string s;
    for (int i = 0; i < 10; ++i) s += "xs 1 1 1 0 0 1 0 0 0 0 { i 0 NEXT }\n";
    return s;
  }();
  for (int level = 1; level <= 12; ++level) {
    std::string text = tenTimes;
    for (std::size_t at; (at = text.find("NEXT")) != std::string::npos;)
      text.replace(at, 4, numberedFile("l", level - 1));
    writeText(dir / numberedFile("l", level), text);
  }
  // 10^12 triangles if expanded.
  EXPECT_TRUE(throwsFileError([&] { anim::importBart((dir / "l12.aff").string()); }, {"expands to more than"}));
}

// ---- errors ---------------------------------------------------------------------------------------

TEST(Bart, MalformedScenesGiveOneLineNamingFileAndLine) {
  struct Case {
    const char* text;
    const char* expected;
  };
  const Case cases[] = {
      {"p 3\n0 0 0\n1 0 0\nzz\n", "scene.aff: line 4: expected polygon vertex coordinate (a finite number), found 'zz'"},
      {"\n\nfrobnicate 1 2\n", "scene.aff: line 3: unknown command 'frobnicate'"},
      {"m\nvertices 3\n0 0 0\n1 0 0\n0 1 0\ntriangles 1\n0 1 5\n", "line 7: triangle 0 uses vertex 5 but the mesh has 3 vertices"},
      {"xs 1 1 1 0 0 1 0 0 0 0 {\np 3 0 0 0 1 0 0 0 1 0\n", "scene.aff: line 1: '{' is never closed"},
      {"p 3 0 0 0 1 0 0 0 1 0\n}\n", "scene.aff: line 2: '}' without a matching '{'"},
      {"k a {\n transl 3\n 0 0 0 0 0 0 0\n", "line 2: key count 3 is out of range [4,"},
      {"k a {\n spin 4\n}\n", "line 2: unknown key type 'spin'"},
      {"a 0 1 0\n", "line 1: frame count 0 is out of range"},
      {"a 1 1 5\n", "line 1: animation end time must be after the start time"},
      {"p 2 0 0 0 1 1 1\n", "line 1: polygon vertex count 2 is out of range [3,"},
      {"m vertices 2000000000 0 0 0\n", "line 1: vertex count 2000000000 is more than the rest of the file can hold"},
      {"tpa 3 0 0 0 0 0 0 0 1 0 0 0 0 0 0 1 0 0 0 0\n", "line 1: animated triangle key count 3 is more than the rest"},
      {"p 3 0 0 0 1 0 0 1e999 0 0\n", "line 1: expected polygon vertex coordinate (a finite number), found '1e999'"},
      {"i 0 missing.aff\n", "scene.aff: line 1: cannot open include file 'missing.aff'"},
      {"c 0 0 0 1 0 0 0 1\n", "line 1: cone base and apex coincide"},
      {"xs 1 1 1 0 0 0 45 0 0 0 { }\n", "line 1: static transform rotates about a zero axis"},
      {"b 0 0 0\n", "the scene holds no triangles"},
      {"x y p 3 0 0 0 1 0 0 0 1 0\n", "line 1: expected '{' after the transform, found 'p'"},
  };
  for (const Case& c : cases) {
    const std::string message = errorOf(c.text);
    EXPECT_NE(message.find(c.expected), std::string::npos) << "scene:\n" << c.text << "\ngave: " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
  }
}

TEST(Bart, HugeFrameCountsAreRefusedBeforeAllocating) {
  const std::string message = errorOf(std::string("a 0 1 2000000000\n") + kTriangle);
  EXPECT_NE(message.find("exceeds the limit"), std::string::npos) << message;
  anim::BartOptions small;
  small.maxPositionBytes = 1000;
  EXPECT_TRUE(
      throwsFileError([&] { loadText(std::string("a 0 1 1000\n") + kTriangle, small); }, {"more than the limit"}));
}

TEST(Bart, LoadDispatchesAffAndPassesFpsAndWarnings) {
  const fs::path file = tsah::test::scratchDir() / "d.aff";
  writeText(file, std::string("a 0 1 3\nfm 1 1 1 1 1 1 1 1 1 1 1 1\n") + kTriangle);
  anim::LoadOptions options;
  options.fps = 10;
  int warnings = 0;
  options.warning = [&](const std::string&) { ++warnings; };
  const auto a = anim::load(file.string(), options);
  EXPECT_EQ(a.keyframeCount(), 11u);
  EXPECT_EQ(warnings, 1);
  EXPECT_EQ(a.name(), "d");
}

// ---- randomized mutations -------------------------------------------------------------------------

// Thousands of mutated scenes: each must load or throw tsah::Error, never crash or hang.
TEST(Bart, RandomMutationsGiveErrorsOrValidAnimations) {
  const fs::path dir = tsah::test::scratchDir();
  writeText(dir / "inc.aff", kTriangle);
  const std::vector<std::string> seeds = {
      "v from 0 0 5 at 0 0 0 up 0 1 0 angle 40 hither 1 resolution 8 8\na 0 2 9\n"
      "m vertices 4 0 0 0 1 0 0 1 1 0 0 1 0 normals 1 0 0 1 texturecoords 1 t.ppm 0 0 "
      "triangles 2 0 1 2 0 0 0 0 0 0 0 2 3 0 0 0 0 0 0\n",
      "xs 2 2 2 0 1 0 30 1 2 3 { x a { p 4 0 0 0 1 0 0 1 1 0 0 1 0 } }\n"
      "k a { transl 4 -1 0 0 0 0 0 0 0 0 0 0 0 0 0 1 1 1 1 0 0 0 2 2 2 2 0 0 0\n"
      " rot 5 -1 0 1 0 0 0 0 0 0 0 1 0 10 0 0 0 1 1 0 0 90 .5 .2 .1 2 0 0 1 45 0 0 0 3 0 1 0 0 0 0 0\n"
      " scale 4 -1 1 1 1 0 0 0 0 1 1 1 0 0 0 1 2 2 2 0 0 0 2 1 1 1 0 0 0\n visibility 2 0.5 0 1.5 1 }\na 0 2 5\n",
      "a -1 1 4\ntpa 2 0 0 0 0 0 0 1 1 0 0 0 0 1 0 1 0 0 0 1 1 0 0 2 0 0 1 3 0 0 0 0 1 0 1 2 0 0 1\n"
      "tt x.ppm 0 0 0 0 0 1 0 0 1 0 0 1 0 0 1\nc 0 0 0 1 0 1 0 0.5\ns 0 0 0 1\n",
      "fm 1 1 1 1 1 1 1 1 1 1 1 1\nl 1 1 1\ni 0 inc.aff\nxs 1 1 1 0 0 1 0 0 0 1 { i 0 inc.aff }\nd 1\ni 1 inc.aff\n"
      "k camera { transl 4 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1 1 1 1 0 0 0 2 2 2 2 0 0 0 }\na 0 1 3\n",
  };
  const std::vector<std::string> tokens = {"{", "}", "m", "p", "x", "xs", "k", "i 0 inc.aff", "i 0 mut.aff", "a", "tpa",
                                           "c", "s", "-1", "0", "1e30", "99999999", "4", "nan", "transl", "rot", ""};
  std::mt19937_64 rng(20240601);
  anim::BartOptions options;
  options.maxPositionBytes = 1 << 20;
  options.maxIncludeDepth = 4;
  const std::vector<std::string> numbers = {"0", "-1", "0.5", "3", "1e6", "-1e-30", "180", "2"};
  const fs::path file = dir / "mut.aff";
  writeText(file, seeds[0]);  // for mutations that include mut.aff itself
  for (const std::string& seed : seeds)  // every seed loads before mutation
    ASSERT_NO_THROW(anim::importBartText(seed, file.string(), options)) << seed;
  int loaded = 0, rejected = 0;
  for (int iteration = 0; iteration < 3000; ++iteration) {
    std::string text = seeds[rng() % seeds.size()];
    const int edits = 1 + int(rng() % 4);
    for (int e = 0; e < edits && !text.empty(); ++e) {
      const std::size_t at = rng() % text.size();
      switch (rng() % 7) {
        case 5:
        case 6: {  // replace the number at or after `at` (keeps the structure, changes values)
          const std::size_t start = text.find_first_of("-0123456789", at);
          if (start == std::string::npos) break;
          const std::size_t end = text.find_first_of(" \n{}", start);
          text.replace(start, (end == std::string::npos ? text.size() : end) - start, numbers[rng() % numbers.size()]);
          break;
        }
        case 0:  // flip a byte
          text[at] = char(rng() % 256);
          break;
        case 1:  // delete a run
          text.erase(at, 1 + rng() % 12);
          break;
        case 2:  // insert a token
          text.insert(at, " " + tokens[rng() % tokens.size()] + " ");
          break;
        case 3:  // duplicate a run
          text.insert(at, text.substr(rng() % text.size(), 1 + rng() % 40));
          break;
        default:  // truncate
          text.resize(at);
      }
    }
    try {
      // Parsed from memory as if it were mut.aff (rewriting a file 3000 times is slow on ext4).
      const auto a = anim::importBartText(text, file.string(), options);
      ASSERT_GT(a.triangleCount(), 0u);
      ASSERT_GT(a.keyframeCount(), 0u);
      ++loaded;
    } catch (const tsah::Error& e) {
      ASSERT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
      ++rejected;
    }
  }
  EXPECT_GT(loaded, 100);
  EXPECT_GT(rejected, 100);
}

// ---- the real BART scenes -------------------------------------------------------------------------

fs::path bartScene(const std::string& folder, const std::string& file) {
  const fs::path root = tsah::test::unpackedData("bart/bart_aff_scenes.tar.xz", folder);
  return root.empty() ? fs::path() : root / file;
}

TEST(BartData, KitchenHasTheBenchmarkCountsAndCameraPath) {
  const fs::path scene = bartScene("kitchen", "kitchen.aff");
  if (scene.empty()) GTEST_SKIP() << "BART data not present";
  const auto a = anim::importBart(scene.string());  // all 800 frames (well under a second)
  EXPECT_EQ(a.triangleCount(), 110561u);
  EXPECT_EQ(a.keyframeCount(), 800u);
  EXPECT_DOUBLE_EQ(a.startTime(), 0.0);
  EXPECT_DOUBLE_EQ(a.endTime(), 20.0);
  EXPECT_EQ(a.cameraPath().size(), 800u);
  // The toy car drives: some vertices move between the first and a middle frame, most stay.
  const auto first = a.keyframe(0), middle = a.keyframe(400);
  std::size_t moved = 0;
  for (std::size_t i = 0; i < first.size(); i += 3)
    if (first[i] != middle[i] || first[i + 1] != middle[i + 1] || first[i + 2] != middle[i + 2]) ++moved;
  EXPECT_GT(moved, 100u);
  EXPECT_LT(moved, first.size() / 3 / 2);
}

TEST(BartData, RobotsHaveTheBenchmarkCounts) {
  const fs::path scene = bartScene("robot", "Robot.aff");
  if (scene.empty()) GTEST_SKIP() << "BART data not present";
  anim::BartOptions options;
  options.fps = 1;  // 51 frames: the counts without the 1.3 GB of all 800
  const auto a = anim::importBart(scene.string(), options);
  EXPECT_EQ(a.triangleCount(), 71708u);
  EXPECT_EQ(a.keyframeCount(), 51u);
  EXPECT_DOUBLE_EQ(a.endTime(), 50.0);
}

TEST(BartData, MuseumCountsStaticAnimatedAndTessellatedCones) {
  const fs::path scene = bartScene("museum", "museum5.aff");
  if (scene.empty()) GTEST_SKIP() << "BART data not present";
  anim::BartOptions options;
  options.fps = 2;
  options.tessellation = 16;
  const auto a = anim::importBart(scene.string(), options);
  // 10,284 static + 1,024 animated triangles, plus 8 open cylinders of 2 x 16 triangles.
  EXPECT_EQ(a.triangleCount(), 10284u + 1024u + 8u * 32u);
  EXPECT_EQ(a.startTime(), -1.0);
  EXPECT_EQ(a.endTime(), 5.0);
}

}  // namespace
