#include <gtest/gtest.h>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/load.hpp"
#include "anim/obj_writer.hpp"
#include "anim/mesh_sequence.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;

using tsah::test::throwsFileError;
using tsah::test::writeText;

// A quad (as one polygon or two triangles) translated by dx.
std::string quadObj(float dx, bool polygon = true) {
  std::string s = "# frame\n";
  for (auto [x, y] : {std::pair{0, 0}, {1, 0}, {1, 1}, {0, 1}})
    s += "v " + std::to_string(float(x) + dx) + " " + std::to_string(y) + " 0\n";
  s += polygon ? "f 1/1/1 2/2/2 3/3/3 4/4/4\n" : "f 1 2 3\nf 1 3 4\n";
  return s;
}

TEST(NaturalOrder, NumbersCompareByValue) {
  EXPECT_TRUE(anim::naturalLess("walk_9.obj", "walk_10.obj"));
  EXPECT_FALSE(anim::naturalLess("walk_10.obj", "walk_9.obj"));
  EXPECT_TRUE(anim::naturalLess("a2b", "a10a"));
  EXPECT_TRUE(anim::naturalLess("f_0009", "f_10"));
  EXPECT_TRUE(anim::naturalLess("abc", "abd"));
  EXPECT_FALSE(anim::naturalLess("x1", "x1"));
}

TEST(ObjReader, TriangulatesPolygonsAndSkipsAttributes) {
  const auto dir = tsah::test::scratchDir();
  writeText(dir / "q.obj", "vt 0 0\nvn 0 0 1\n" + quadObj(0) + "f -4 -3 -2\n");
  const anim::MeshFrame m = anim::readMesh((dir / "q.obj").string());
  EXPECT_EQ(m.positions.size(), 12u);
  EXPECT_EQ(m.faceCount, 2u);
  EXPECT_EQ(m.polygonsTriangulated, 1u);
  ASSERT_EQ(m.indices.size(), 9u);  // fan of the quad + the relative-index triangle
  EXPECT_EQ((std::vector<uint32_t>(m.indices.begin(), m.indices.begin() + 6)),
            (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
  EXPECT_EQ(m.indices[6], 0u);
}

TEST(ObjReader, ErrorsNameFileAndLine) {
  const auto dir = tsah::test::scratchDir();
  writeText(dir / "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n");
  EXPECT_TRUE(throwsFileError([&] { anim::readMesh((dir / "bad.obj").string()); }, {"bad.obj: line 4"}));
  writeText(dir / "nan.obj", "v 0 0 x\n");
  EXPECT_THROW(anim::readMesh((dir / "nan.obj").string()), tsah::FileError);
  EXPECT_THROW(anim::readMesh((dir / "missing.obj").string()), tsah::FileError);
}

TEST(OtherFormats, OffThroughOpenMesh) {
  const auto dir = tsah::test::scratchDir();
  writeText(dir / "q.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n");
  const anim::Animation a = anim::load((dir / "q.off").string());
  EXPECT_EQ(a.triangleCount(), 2u);
  EXPECT_EQ(a.vertexCount(), 4u);
  EXPECT_EQ(a.keyframeCount(), 1u);
}

TEST(OtherFormats, NonManifoldFacesAreAnErrorNotSilentlyDropped) {
  // Three triangles on one edge: a half-edge mesh cannot hold the third, so the topology would change.
  const auto dir = tsah::test::scratchDir();
  writeText(dir / "nm.off", "OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 1 4\n");
  EXPECT_TRUE(throwsFileError([&] { anim::load((dir / "nm.off").string()); }, {"non-manifold"}));
}

class Sequence : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = tsah::test::scratchDir();
    // Written out of order on purpose; 10 must come after 9.
    for (int i : {10, 2, 9, 1, 0}) {
      char name[32];
      std::snprintf(name, sizeof name, "walk_%d.obj", i);
      writeText(dir / name, quadObj(float(i)));
    }
    writeText(dir / "notes.txt", "not a mesh");
  }
  fs::path dir;
};

TEST_F(Sequence, DirectoryInNaturalOrder) {
  const auto a = anim::load(dir.string());
  ASSERT_EQ(a.keyframeCount(), 5u);
  const float expected[5] = {0, 1, 2, 9, 10};
  for (uint32_t k = 0; k < 5; ++k) EXPECT_FLOAT_EQ(a.keyframe(k)[0], expected[k]);
  EXPECT_EQ(a.triangleCount(), 2u);
}

TEST_F(Sequence, PrintfPatternAndGlob) {
  const auto a = anim::load((dir / "walk_%d.obj").string());
  EXPECT_EQ(a.keyframeCount(), 5u);
  EXPECT_FLOAT_EQ(a.keyframe(4)[0], 10.0f);
  const auto b = anim::load((dir / "walk_*.obj").string());
  EXPECT_EQ(b.keyframeCount(), 5u);
  EXPECT_FLOAT_EQ(b.keyframe(3)[0], 9.0f);
  EXPECT_THROW(anim::load((dir / "run_%d.obj").string()), tsah::FileError);
  EXPECT_THROW(anim::load((dir / "walk_%s.obj").string()), tsah::FileError);
}

TEST_F(Sequence, ZeroPaddedPattern) {
  const auto d = tsah::test::scratchDir();
  for (int i : {1, 2, 10}) {
    char name[32];
    std::snprintf(name, sizeof name, "f_%04d.obj", i);
    writeText(d / name, quadObj(float(i)));
  }
  const auto a = anim::load((d / "f_%04d.obj").string());
  ASSERT_EQ(a.keyframeCount(), 3u);
  EXPECT_FLOAT_EQ(a.keyframe(2)[0], 10.0f);
}

TEST(FramePatterns, LiteralCharactersShortNumbersAndHugeNumbers) {
  const auto d = tsah::test::scratchDir();
  // Regex metacharacters and a literal percent in the name are plain text; a zero-padded pattern
  // skips numbers with fewer digits; a number past 64 bits is not a frame (not a crash).
  const std::pair<const char*, float> files[] = {{"a+b(1)%_001.obj", 1.0f},
                                                  {"a+b(1)%_002.obj", 2.0f},
                                                  {"a+b(1)%_3.obj", 3.0f},
                                                  {"a+b(1)%_0x4.obj", 4.0f},
                                                  {"a+b(1)%_123456789012345678901234567890.obj", 5.0f},
                                                  {"a+b(1)%_005.obj.bak", 6.0f}};
  for (const auto& [name, x] : files) writeText(d / name, quadObj(x));
  const auto a = anim::load((d / "a+b(1)%%_%03d.obj").string());
  ASSERT_EQ(a.keyframeCount(), 2u);
  EXPECT_FLOAT_EQ(a.keyframe(1)[0], 2.0f);
  EXPECT_TRUE(throwsFileError([&] { anim::load((d / "a%d_%d.obj").string()); }, {"exactly one"}));
  EXPECT_TRUE(throwsFileError([&] { anim::load((d / "a%0100d.obj").string()); }, {"width"}));
  EXPECT_TRUE(throwsFileError([&] { anim::load((d / "a_%%.obj").string()); }, {"no %d"}));
}

TEST(FramePatterns, WrittenSequenceReadsBack) {
  // The writer formats the number itself (the pattern is never a printf format): "%%" is a
  // percent, "%3d" pads with spaces as printf does; anything but one %d-style number is refused.
  const auto d = tsah::test::scratchDir();
  const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 60, 3);
  EXPECT_EQ(anim::saveObjSequence(wave, (d / "w%%_%03d.obj").string()), 3u);
  EXPECT_TRUE(fs::exists(d / "w%_001.obj"));
  const anim::Animation back = anim::load((d / "w%%_%03d.obj").string());
  ASSERT_EQ(back.keyframeCount(), 3u);
  EXPECT_FLOAT_EQ(back.keyframe(2)[5], wave.keyframe(2)[5]);
  EXPECT_EQ(anim::saveObjSequence(wave, (d / "s_%3d.obj").string()), 3u);
  EXPECT_TRUE(fs::exists(d / "s_  3.obj"));
  for (const char* bad : {"x_%s.obj", "x_%d_%d.obj", "x.obj", "x_%n.obj"})
    EXPECT_THROW(anim::saveObjSequence(wave, (d / bad).string()), tsah::ConfigError) << bad;
}

TEST_F(Sequence, ManifestWithTimes) {
  writeText(dir / "m.json",
            R"({"frames": [{"file": "walk_0.obj", "time": 0.5}, {"file": "walk_2.obj", "time": 1.5}]})");
  const auto a = anim::load((dir / "m.json").string());
  ASSERT_EQ(a.keyframeCount(), 2u);
  EXPECT_DOUBLE_EQ(a.startTime(), 0.5);
  EXPECT_FLOAT_EQ(a.positionsAt(1.0)[0], 1.0f);
  writeText(dir / "bare.json", R"(["walk_0.obj", "walk_1.obj", "walk_2.obj"])");
  EXPECT_EQ(anim::load((dir / "bare.json").string()).keyframeCount(), 3u);
  writeText(dir / "partial.json", R"([{"file": "walk_0.obj", "time": 1}, "walk_1.obj"])");
  EXPECT_THROW(anim::load((dir / "partial.json").string()), tsah::FileError);
  writeText(dir / "backwards.json", R"([{"file": "walk_0.obj", "time": 2}, {"file": "walk_1.obj", "time": 1}])");
  EXPECT_THROW(anim::load((dir / "backwards.json").string()), tsah::FileError);
  writeText(dir / "broken.json", "{\"frames\": [");
  EXPECT_THROW(anim::load((dir / "broken.json").string()), tsah::FileError);
}

TEST_F(Sequence, TopologyMismatchNamesTheFirstDifferingFile) {
  writeText(dir / "walk_5.obj", quadObj(5.0f, /*polygon=*/false) + "f 2 3 4\n");  // an extra face
  EXPECT_TRUE(throwsFileError([&] { anim::load(dir.string()); }, {"walk_5.obj", "triangles"}));
  writeText(dir / "walk_5.obj", "v 0 0 0\n" + quadObj(5.0f));  // an extra vertex
  EXPECT_TRUE(throwsFileError([&] { anim::load(dir.string()); }, {"walk_5.obj: has 5 vertices"}));
}

TEST_F(Sequence, SameCountsDifferentFacesIsAnError) {
  // Two explicit triangles equal to the fan of the quad: the same topology, so it loads.
  writeText(dir / "walk_3.obj", quadObj(3.0f, /*polygon=*/false));
  EXPECT_NO_THROW(anim::load(dir.string()));
  std::string swapped = quadObj(3.0f, false);
  swapped.replace(swapped.find("f 1 3 4"), 7, "f 1 4 3");
  writeText(dir / "walk_3.obj", swapped);
  EXPECT_THROW(anim::load(dir.string()), tsah::FileError);
}

TEST_F(Sequence, NanCoordinateIsAnError) {
  writeText(dir / "walk_4.obj", "v nan 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
  EXPECT_TRUE(throwsFileError([&] { anim::load(dir.string()); }, {"walk_4.obj"}));
}

TEST(RealData, HorseGallopCountsAndFirstFrameBounds) {
  const auto dir = tsah::test::unpackedData("sequences/horse-gallop.tar.xz", "horse-gallop");
  if (dir.empty()) GTEST_SKIP() << "real data not available";
  const auto a = anim::load(dir.string());
  EXPECT_EQ(a.keyframeCount(), 48u);
  EXPECT_EQ(a.triangleCount(), 16843u);
  // The data README: frame 1 bounding box x ±0.20, y 0.01..1.36, z −1.34..0.78.
  const auto b = a.keyframeBounds(0);
  EXPECT_NEAR(b.min[0], -0.20, 0.01);
  EXPECT_NEAR(b.max[0], 0.20, 0.01);
  EXPECT_NEAR(b.min[1], 0.01, 0.01);
  EXPECT_NEAR(b.max[1], 1.36, 0.01);
  EXPECT_NEAR(b.min[2], -1.34, 0.01);
  EXPECT_NEAR(b.max[2], 0.78, 0.01);
}

TEST(RealData, CollapseAndSambaCounts) {
  const auto collapse = tsah::test::unpackedData("sequences/horse-collapse.tar.xz", "horse-collapse");
  const auto samba = tsah::test::unpackedData("sequences/samba.tar.xz", "samba");
  if (collapse.empty() || samba.empty()) GTEST_SKIP() << "real data not available";
  const auto c = anim::load(collapse.string());
  EXPECT_EQ(c.keyframeCount(), 53u);
  EXPECT_EQ(c.triangleCount(), 16843u);
  const auto s = anim::load(samba.string());
  EXPECT_EQ(s.keyframeCount(), 175u);
  EXPECT_EQ(s.triangleCount(), 19938u);
}

}  // namespace
