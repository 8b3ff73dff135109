// PC2 and MDD point caches: hand-written files in both byte orders, round trips through the
// encoders and through files paired with a mesh, corrupt / truncated / absurd inputs, the input
// forms of anim::load (the fuzz seed corpora are replayed by test_fuzz_corpora).
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/load.hpp"
#include "anim/mesh_sequence.hpp"
#include "anim/obj_writer.hpp"
#include "anim/point_cache.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
using anim::PointCacheFormat;

// Bytes written field by field in an explicit byte order, independent of the code under test.
struct Bytes {
  bool bigEndian = false;
  std::vector<uint8_t> data;

  Bytes& u32(uint32_t v) {
    for (int i = 0; i < 4; ++i) data.push_back(uint8_t(v >> (bigEndian ? 24 - 8 * i : 8 * i)));
    return *this;
  }
  Bytes& i32(int32_t v) { return u32(std::bit_cast<uint32_t>(v)); }
  Bytes& f32(float v) { return u32(std::bit_cast<uint32_t>(v)); }
  Bytes& text(const char* s, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) data.push_back(uint8_t(s[i]));
    return *this;
  }
};

Bytes pc2Header(int32_t points, float start, float rate, int32_t samples, int32_t version = 1) {
  Bytes b;
  b.text("POINTCACHE2\0", 12).i32(version).i32(points).f32(start).f32(rate).i32(samples);
  return b;
}

Bytes mddHeader(int32_t frames, int32_t points) {
  Bytes b{true, {}};
  b.i32(frames).i32(points);
  return b;
}

// 2 frames of 3 points: frame f, point p, axis a holds f*100 + p*10 + a.
float value(int f, int p, int a) { return float(f * 100 + p * 10 + a); }
Bytes& addFrames(Bytes& b, int frames, int points) {
  for (int f = 0; f < frames; ++f)
    for (int p = 0; p < points; ++p)
      for (int a = 0; a < 3; ++a) b.f32(value(f, p, a));
  return b;
}

std::vector<uint8_t> withFrames(Bytes b, int frames, int points) { return addFrames(b, frames, points).data; }

std::string errorOf(std::span<const uint8_t> bytes, PointCacheFormat format) {
  try {
    anim::decodePointCache(bytes, "cache.bin", format);
  } catch (const tsah::FileError& e) {
    return e.what();
  }
  return "";
}

anim::Animation smallWave() {
  return tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 200, 6, 4);
}

void expectSameAnimation(const anim::Animation& a, const anim::Animation& b) {
  ASSERT_EQ(a.vertexCount(), b.vertexCount());
  ASSERT_EQ(a.keyframeCount(), b.keyframeCount());
  EXPECT_TRUE(std::equal(a.indices().begin(), a.indices().end(), b.indices().begin(), b.indices().end()));
  EXPECT_TRUE(std::equal(a.times().begin(), a.times().end(), b.times().begin(), b.times().end()));
  EXPECT_EQ(a.allPositions(), b.allPositions());
}

TEST(PointCache, HandWrittenPc2LittleEndian) {
  Bytes b = pc2Header(3, 10.0f, 0.5f, 2);
  const anim::PointCache c = anim::decodePc2(addFrames(b, 2, 3).data, "a.pc2");
  EXPECT_EQ(c.pointCount, 3u);
  ASSERT_EQ(c.times.size(), 2u);
  EXPECT_EQ(c.times[0], 10.0);
  EXPECT_EQ(c.times[1], 10.5);  // start frame + i * sample rate
  ASSERT_EQ(c.positions.size(), 18u);
  EXPECT_EQ(c.positions[0], value(0, 0, 0));
  EXPECT_EQ(c.positions[3 * 2 + 1], value(0, 2, 1));
  EXPECT_EQ(c.positions[9 + 3 * 1 + 2], value(1, 1, 2));
  EXPECT_FALSE(c.skippedRestFrame);
}

TEST(PointCache, HandWrittenMddBigEndian) {
  Bytes b = mddHeader(2, 3);
  b.f32(0.0f).f32(1.0f / 24.0f);
  const anim::PointCache c = anim::decodeMdd(addFrames(b, 2, 3).data, "a.mdd");
  EXPECT_EQ(c.pointCount, 3u);
  ASSERT_EQ(c.times.size(), 2u);
  EXPECT_EQ(c.times[1], double(1.0f / 24.0f));
  EXPECT_EQ(c.positions[9 + 3 * 2 + 0], value(1, 2, 0));
  // The same bytes read in the other byte order are garbage that must be rejected, not accepted.
  EXPECT_NE(errorOf(b.data, PointCacheFormat::Pc2), "");
}

TEST(PointCache, MddRestFrameOfBlendersExporterIsSkipped) {
  Bytes b = mddHeader(2, 3);
  b.f32(0.0f).f32(1.0f);
  for (int i = 0; i < 9; ++i) b.f32(-7.0f);  // the rest pose block
  const anim::PointCache c = anim::decodeMdd(addFrames(b, 2, 3).data, "a.mdd");
  EXPECT_TRUE(c.skippedRestFrame);
  EXPECT_EQ(c.positions.front(), value(0, 0, 0));
  EXPECT_EQ(c.positions.back(), value(1, 2, 2));
}

TEST(PointCache, EncodersWriteTheDocumentedBytes) {
  const anim::Animation a({0, 1, 2}, 3, std::vector<float>(18, 1.5f), {4.0, 6.0}, "t");
  Bytes pc2 = pc2Header(3, 4.0f, 2.0f, 2);
  for (int i = 0; i < 18; ++i) pc2.f32(1.5f);
  EXPECT_EQ(anim::encodePc2(a), pc2.data);
  Bytes mdd = mddHeader(2, 3);
  mdd.f32(4.0f).f32(6.0f);
  for (int i = 0; i < 18; ++i) mdd.f32(1.5f);
  EXPECT_EQ(anim::encodeMdd(a), mdd.data);
}

TEST(PointCache, RoundTripThroughBothEncoders) {
  const anim::Animation a = smallWave();
  for (PointCacheFormat f : {PointCacheFormat::Pc2, PointCacheFormat::Mdd}) {
    const auto bytes = f == PointCacheFormat::Pc2 ? anim::encodePc2(a) : anim::encodeMdd(a);
    const anim::PointCache c = anim::decodePointCache(bytes, "x", f);
    EXPECT_EQ(c.pointCount, a.vertexCount());
    EXPECT_TRUE(std::equal(c.times.begin(), c.times.end(), a.times().begin(), a.times().end()));
    EXPECT_EQ(std::vector<float>(c.positions.begin(), c.positions.end()), a.allPositions());
  }
}

TEST(PointCache, Pc2RefusesTimesOffAUniformGrid) {
  const anim::Animation a({0, 1, 2}, 3, std::vector<float>(27, 0.0f), {0.0, 1.0, 3.0}, "uneven");
  try {
    anim::encodePc2(a);
    FAIL() << "accepted uneven times";
  } catch (const tsah::Error& e) {
    EXPECT_NE(std::string(e.what()).find("--frames"), std::string::npos) << e.what();
  }
  // MDD keeps every time.
  EXPECT_EQ(anim::decodeMdd(anim::encodeMdd(a), "u.mdd").times[2], 3.0);
}

TEST(PointCache, TimesBeyondFloat32AreRefusedBeforeAnyFileIsWritten) {
  const fs::path dir = tsah::test::scratchDir();
  auto refusal = [&](const anim::Animation& a, const char* file) -> std::string {
    try {
      anim::savePointCache(a, (dir / file).string());
    } catch (const tsah::DataError& e) {
      EXPECT_FALSE(fs::exists(dir / file)) << file;
      return e.what();
    }
    return "written";
  };
  const anim::Animation late({0, 1, 2}, 3, std::vector<float>(18, 0.0f), {0.0, 1e39}, "late");
  EXPECT_EQ(refusal(late, "late.pc2"), "late: keyframe 1 at time 1e+39 does not fit the float32 times of the PC2 format");
  EXPECT_EQ(refusal(late, "late.mdd"), "late: keyframe 1 at time 1e+39 does not fit the float32 times of the MDD format");
  // Each time fits, the step between them does not.
  const anim::Animation wide({0, 1, 2}, 3, std::vector<float>(18, 0.0f), {-3e38, 3e38}, "wide");
  EXPECT_EQ(refusal(wide, "wide.pc2"), "wide: the step 6e+38 between keyframes does not fit the float32 sample rate "
                                       "of the PC2 format");
  EXPECT_EQ(anim::decodeMdd(anim::encodeMdd(wide), "w.mdd").times[1], double(3e38f));
}

TEST(PointCache, PairedWithAMeshThroughEveryInputForm) {
  const fs::path dir = tsah::test::scratchDir();
  const anim::Animation a = smallWave();
  const std::string mesh = (dir / "wave.obj").string();
  anim::saveObjFrame(a, 0, mesh);
  for (const char* ext : {".pc2", ".mdd"}) {
    const std::string cache = (dir / (std::string("wave") + ext)).string();
    anim::savePointCache(a, cache);
    expectSameAnimation(a, anim::load(mesh + "+" + cache));
    std::ofstream(dir / "pair.json") << R"({"mesh": "wave.obj", "cache": "wave)" << ext << "\"}";
    expectSameAnimation(a, anim::load((dir / "pair.json").string()));
  }
  // A frame-list manifest still loads as before.
  std::ofstream(dir / "frames.json") << R"({"frames": ["wave.obj", "wave.obj"]})";
  EXPECT_EQ(anim::load((dir / "frames.json").string()).keyframeCount(), 2u);
}

TEST(PointCache, InputFormsAndTheirErrors) {
  auto split = anim::splitPointCacheInput("dir+x/m+1.obj+c+d.PC2");
  ASSERT_TRUE(split);
  EXPECT_EQ(split->mesh, "dir+x/m+1.obj");
  EXPECT_EQ(split->cache, "c+d.PC2");
  EXPECT_FALSE(anim::splitPointCacheInput("a.obj"));
  EXPECT_FALSE(anim::splitPointCacheInput("a+b.pc2"));  // the left side is not a mesh file

  const fs::path dir = tsah::test::scratchDir();
  const anim::Animation a = smallWave();
  anim::saveObjFrame(a, 0, (dir / "m.obj").string());
  anim::savePointCache(a, (dir / "c.pc2").string());
  auto loadError = [](const std::string& input) -> std::string {
    try {
      anim::load(input);
    } catch (const tsah::FileError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(loadError((dir / "c.pc2").string()).find("mesh.obj+c.pc2"), std::string::npos);  // cache alone
  // A mesh with other points: the cache is named with both counts.
  const anim::Animation other({0, 1, 2}, 3, std::vector<float>(9, 0.0f), {0.0}, "tri");
  anim::saveObjFrame(other, 0, (dir / "tri.obj").string());
  const std::string mismatch = loadError((dir / "tri.obj").string() + "+" + (dir / "c.pc2").string());
  EXPECT_NE(mismatch.find("c.pc2: holds " + std::to_string(a.vertexCount()) + " points"), std::string::npos) << mismatch;
  EXPECT_NE(mismatch.find("has 3 vertices"), std::string::npos) << mismatch;
  EXPECT_NE(loadError((dir / "m.obj").string() + "+" + (dir / "none.mdd").string()).find("none.mdd"), std::string::npos);
  std::ofstream(dir / "bad.json") << R"({"cache": 3})";
  EXPECT_NE(loadError((dir / "bad.json").string()).find("\"mesh\" and \"cache\""), std::string::npos);
}

TEST(PointCache, CorruptAndAbsurdFilesGiveOneLineErrors) {
  struct Case {
    const char* name;
    std::vector<uint8_t> bytes;
    PointCacheFormat format;
    const char* expected;
  };
  Bytes goodPc2 = pc2Header(3, 0, 1, 2);
  addFrames(goodPc2, 2, 3);
  std::vector<uint8_t> badSignature = goodPc2.data;
  badSignature[5] = 'X';
  Bytes nanPc2 = pc2Header(3, 0, 1, 1);
  for (int i = 0; i < 9; ++i) nanPc2.f32(i == 4 ? std::numeric_limits<float>::quiet_NaN() : 1.0f);
  // Fuzz finding (fuzz_pc2, fuzz_mdd): a coordinate past kMaxCoordinate was accepted here and refused
  // later by the Animation under the cache's stem, not its file name.
  Bytes hugePc2 = pc2Header(3, 0, 1, 1);
  for (int i = 0; i < 9; ++i) hugePc2.f32(i == 4 ? 1e30f : 1.0f);
  Bytes extra = goodPc2;
  extra.f32(1.0f);
  Bytes nanTime = mddHeader(2, 1);
  nanTime.f32(0.0f).f32(std::numeric_limits<float>::quiet_NaN());
  addFrames(nanTime, 2, 1);
  Bytes backwards = mddHeader(2, 1);
  backwards.f32(1.0f).f32(1.0f);
  addFrames(backwards, 2, 1);
  const std::vector<Case> cases = {
      {"signature", badSignature, PointCacheFormat::Pc2, "not a PC2 file"},
      {"version", withFrames(pc2Header(3, 0, 1, 2, 2), 2, 3), PointCacheFormat::Pc2, "version 2"},
      {"no points", pc2Header(0, 0, 1, 2).data, PointCacheFormat::Pc2, "point count 0 is absurd"},
      {"negative samples", pc2Header(3, 0, 1, -5).data, PointCacheFormat::Pc2, "sample count -5 is absurd"},
      {"zero rate", withFrames(pc2Header(3, 0, 0, 2), 2, 3), PointCacheFormat::Pc2, "sample rate"},
      // Counts that would need terabytes: refused from the file size, before any allocation.
      {"huge pc2", pc2Header(INT32_MAX, 0, 1, INT32_MAX).data, PointCacheFormat::Pc2, "truncated"},
      {"huge mdd", mddHeader(INT32_MAX, INT32_MAX).data, PointCacheFormat::Mdd, "truncated: frame times"},
      {"huge mdd points", [] { Bytes b = mddHeader(1, INT32_MAX); return b.f32(0).data; }(), PointCacheFormat::Mdd, "truncated"},
      {"trailing bytes", extra.data, PointCacheFormat::Pc2, "4 bytes follow"},
      {"nan coordinate", nanPc2.data, PointCacheFormat::Pc2, "frame 0, point 1 has a NaN"},
      {"huge coordinate", hugePc2.data, PointCacheFormat::Pc2,
       "frame 0, point 1 has coordinate 1e+30, beyond the supported magnitude 1e+18"},
      {"nan time", nanTime.data, PointCacheFormat::Mdd, "non-finite time"},
      {"equal times", backwards.data, PointCacheFormat::Mdd, "is not after"},
      {"negative frames", mddHeader(-1, 3).data, PointCacheFormat::Mdd, "frame count -1 is absurd"},
      {"empty", {}, PointCacheFormat::Mdd, "truncated"},
  };
  for (const Case& c : cases) {
    const std::string error = errorOf(c.bytes, c.format);
    EXPECT_NE(error.find(c.expected), std::string::npos) << c.name << ": " << error;
    EXPECT_EQ(error.rfind("cache.bin: ", 0), 0u) << c.name << ": " << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << c.name;
  }
}

TEST(PointCache, EveryTruncationIsRejected) {
  const anim::Animation a({0, 1, 2}, 3, std::vector<float>(18, 2.0f), {0.0, 1.0}, "t");
  for (PointCacheFormat f : {PointCacheFormat::Pc2, PointCacheFormat::Mdd}) {
    const auto bytes = f == PointCacheFormat::Pc2 ? anim::encodePc2(a) : anim::encodeMdd(a);
    for (std::size_t n = 0; n < bytes.size(); ++n)
      EXPECT_NE(errorOf(std::span(bytes).first(n), f), "") << "prefix of " << n << " bytes accepted";
  }
}

// Done-when check of issue 16: a PC2 written from samba reads back identically.
TEST(PointCache, SambaThroughPc2ReadsBackIdentically) {
  const fs::path samba = tsah::test::unpackedData("sequences/samba.tar.xz", "samba");
  if (samba.empty()) GTEST_SKIP() << "real data not available";
  const anim::Animation a = anim::load(samba.string());
  const fs::path dir = tsah::test::scratchDir();
  anim::savePointCache(a, (dir / "samba.pc2").string());
  anim::saveObjFrame(a, 0, (dir / "samba.obj").string());
  expectSameAnimation(a, anim::load((dir / "samba.obj").string() + "+" + (dir / "samba.pc2").string()));
}

}  // namespace
