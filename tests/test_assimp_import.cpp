// Animated model import: MD2 keyframes (real files and synthetic, corrupted ones), glTF skinning,
// morph targets and node animation against hand-computed positions (the test writes the glTF
// files), clip choice, and a few of Debian's assimp-testmodels.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "anim/assimp_import.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "anim/load.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
using tsah::test::writeText;

std::array<float, 3> vertexAt(const anim::Animation& a, double t, uint32_t v) {
  const auto p = a.positionsAt(t);
  return {p[3 * v], p[3 * v + 1], p[3 * v + 2]};
}

void expectNear(const std::array<float, 3>& p, std::array<double, 3> q, const char* what) {
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(p[i], q[i], 1e-5) << what << " coordinate " << i;
}

// ---- MD2 --------------------------------------------------------------------------------------------

fs::path md2Data(const char* name) {
  const fs::path p = tsah::test::dataDir() / "md2" / name;
  return fs::exists(p) ? p : fs::path();
}

TEST(Md2Data, FaerieAndSydneyKeepEveryKeyframe) {
  const fs::path faerie = md2Data("faerie.md2"), sydney = md2Data("sydney.md2");
  if (faerie.empty() || sydney.empty()) GTEST_SKIP() << "MD2 data not present";
  const auto f = anim::load(faerie.string());
  EXPECT_EQ(f.triangleCount(), 654u);
  EXPECT_EQ(f.keyframeCount(), 198u);
  EXPECT_NEAR(f.endTime(), 19.7, 1e-12);  // 10 keyframes per second
  const auto s = anim::load(sydney.string());
  EXPECT_EQ(s.triangleCount(), 679u);
  EXPECT_EQ(s.keyframeCount(), 198u);
  // The keyframes differ: the model really animates.
  EXPECT_NE(f.keyframe(0), f.keyframe(50));
}

TEST(Md2Data, ClipsGroupFramesByName) {
  const fs::path faerie = md2Data("faerie.md2");
  if (faerie.empty()) GTEST_SKIP() << "MD2 data not present";
  const auto clips = anim::modelClips(faerie.string());
  ASSERT_GE(clips.size(), 2u);
  EXPECT_EQ(clips[0], "stand");
  anim::LoadOptions options;
  options.clip = clips[1];
  options.fps = 5;
  const auto byName = anim::load(faerie.string(), options);
  options.clip = "1";
  const auto byIndex = anim::load(faerie.string(), options);
  EXPECT_LT(byName.keyframeCount(), 198u);
  EXPECT_EQ(byName.keyframeCount(), byIndex.keyframeCount());
  EXPECT_DOUBLE_EQ(byName.times()[1], 0.2);
  options.clip = "no-such-clip";
  EXPECT_TRUE(tsah::test::throwsFileError([&] { anim::load(faerie.string(), options); }, {"clips: stand, "}));
}

// A small valid MD2: 4 vertices, 2 triangles, 3 frames named walk1, walk2, jump1.
std::vector<uint8_t> makeMd2() {
  const int32_t numVerts = 4, numTris = 2, numFrames = 3, frameSize = 40 + 4 * numVerts;
  const int32_t offTris = 68, offFrames = offTris + 12 * numTris, offEnd = offFrames + numFrames * frameSize;
  tsah::ByteWriter w;
  w.append("IDP2", 4);
  for (int32_t v : {8, 64, 64, frameSize, 0, numVerts, 0, numTris, 0, numFrames, 68, 68, offTris, offFrames, offEnd, offEnd})
    w.write(v);
  for (int v : {0, 1, 2, 0, 0, 0, 0, 2, 3, 0, 0, 0}) w.write(uint16_t(v));
  const char* names[3] = {"walk1", "walk2", "jump1"};
  for (int f = 0; f < numFrames; ++f) {
    for (float s : {0.5f, 0.5f, 0.5f}) w.write(s);
    for (float t : {float(f), -1.0f, 10.0f}) w.write(t);
    char name[16] = {};
    std::strcpy(name, names[f]);
    w.append(name, 16);
    const uint8_t verts[4][4] = {{0, 0, 0, 0}, {2, 0, 0, 0}, {2, 2, 0, 0}, {0, 2, 4, 0}};
    for (const auto& v : verts) w.append(v, 4);
  }
  return w.buffer();
}

TEST(Md2, DecodesPositionsAsScaledBytesPlusTranslation) {
  const auto a = anim::decodeMd2(makeMd2(), "synthetic.md2");
  EXPECT_EQ(a.triangleCount(), 2u);
  EXPECT_EQ(a.vertexCount(), 4u);
  ASSERT_EQ(a.keyframeCount(), 3u);
  EXPECT_DOUBLE_EQ(a.times()[2], 0.2);
  // Frame 2, vertex 3: bytes (0,2,4) * 0.5 + (2,-1,10).
  const auto p = a.keyframe(2);
  EXPECT_EQ(p[9], 2.0f);
  EXPECT_EQ(p[10], 0.0f);
  EXPECT_EQ(p[11], 12.0f);
  EXPECT_EQ(anim::md2Clips(makeMd2(), "synthetic.md2"), (std::vector<std::string>{"walk", "jump"}));
  anim::LoadOptions options;
  options.clip = "jump";
  EXPECT_EQ(anim::decodeMd2(makeMd2(), "synthetic.md2", options).keyframeCount(), 1u);
}

void patchInt(std::vector<uint8_t>& b, std::size_t offset, int32_t value) { std::memcpy(&b[offset], &value, 4); }

TEST(Md2, CorruptHeadersAndIndicesAreRefused) {
  struct Case {
    std::size_t offset;
    int32_t value;
    const char* expected;
  };
  const Case cases[] = {
      {0, 0x41414141, "not an MD2 file"},
      {4, 7, "unsupported MD2 version 7"},
      {24, 0, "vertex count 0 is out of range"},
      {24, 100000, "vertex count 100000 is out of range"},
      {16, 8, "frame size 8 is too small"},
      {40, 0x7fffffff, "frame block"},
      {52, -5, "triangle block"},
      {56, 1 << 30, "frame block"},
  };
  for (const Case& c : cases) {
    auto bytes = makeMd2();
    patchInt(bytes, c.offset, c.value);
    try {
      anim::decodeMd2(bytes, "bad.md2");
      ADD_FAILURE() << "accepted a corrupt header (offset " << c.offset << ")";
    } catch (const tsah::FileError& e) {
      EXPECT_NE(std::string(e.what()).find(c.expected), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).rfind("bad.md2", 0), 0u) << e.what();
    }
  }
  auto badIndex = makeMd2();
  badIndex[68 + 2] = 9;  // triangle 0, second vertex index 9 of 4
  EXPECT_THROW(anim::decodeMd2(badIndex, "bad.md2"), tsah::FileError);
  auto truncated = makeMd2();
  truncated.resize(truncated.size() - 1);
  EXPECT_THROW(anim::decodeMd2(truncated, "bad.md2"), tsah::FileError);
  EXPECT_THROW(anim::decodeMd2(std::vector<uint8_t>(10, 0), "bad.md2"), tsah::FileError);
}

TEST(Md2, RandomByteMutationsGiveErrorsOrValidAnimations) {
  std::mt19937 rng(7);
  const auto good = makeMd2();
  int loaded = 0;
  for (int i = 0; i < 3000; ++i) {
    auto bytes = good;
    for (int e = 0; e < 1 + int(rng() % 3); ++e) bytes[rng() % bytes.size()] = uint8_t(rng());
    try {
      const auto a = anim::decodeMd2(bytes, "m.md2");
      EXPECT_GT(a.triangleCount(), 0u);
      ++loaded;
    } catch (const tsah::FileError&) {
    }
  }
  EXPECT_GT(loaded, 100);
}

// ---- glTF written by the test ---------------------------------------------------------------------

std::string base64(const std::vector<uint8_t>& in) {
  static const char* abc = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (std::size_t i = 0; i < in.size(); i += 3) {
    const uint32_t n = (uint32_t(in[i]) << 16) | (i + 1 < in.size() ? uint32_t(in[i + 1]) << 8 : 0) |
                       (i + 2 < in.size() ? uint32_t(in[i + 2]) : 0);
    out += abc[(n >> 18) & 63];
    out += abc[(n >> 12) & 63];
    out += i + 1 < in.size() ? abc[(n >> 6) & 63] : '=';
    out += i + 2 < in.size() ? abc[n & 63] : '=';
  }
  return out;
}

// Collects binary arrays into one embedded buffer and writes their bufferViews and accessors. Each
// array's accessor index is returned as text, for the JSON that refers to it.
class GltfData {
 public:
  std::string floats(const std::vector<float>& v, const char* type, bool withBounds = false) {
    std::string extra;
    if (withBounds) {  // glTF requires min/max on POSITION accessors (3 components)
      float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
      for (std::size_t i = 0; i < v.size(); ++i) {
        lo[i % 3] = std::min(lo[i % 3], v[i]);
        hi[i % 3] = std::max(hi[i % 3], v[i]);
      }
      extra = ",\"min\":[" + num(lo[0]) + "," + num(lo[1]) + "," + num(lo[2]) + "],\"max\":[" + num(hi[0]) + "," +
              num(hi[1]) + "," + num(hi[2]) + "]";
    }
    const int components = std::string(type) == "SCALAR" ? 1 : std::string(type) == "VEC3" ? 3 : std::string(type) == "VEC4" ? 4 : 16;
    if (std::string(type) == "SCALAR" && !v.empty()) {  // animation inputs need min/max too
      extra = ",\"min\":[" + num(*std::min_element(v.begin(), v.end())) + "],\"max\":[" +
              num(*std::max_element(v.begin(), v.end())) + "]";
    }
    return add(v.data(), v.size() * 4, 5126, int(v.size()) / components, type, extra);
  }
  std::string ushorts(const std::vector<uint16_t>& v, const char* type) {
    const int components = std::string(type) == "SCALAR" ? 1 : 4;
    return add(v.data(), v.size() * 2, 5123, int(v.size()) / components, type, "");
  }
  // Writes the glTF file `path`: the asset header, the scene of the root nodes `roots` ("0,1"), `body`
  // (nodes, meshes, skins, animations: each followed by a comma) and this data.
  fs::path write(const fs::path& path, const std::string& roots, const std::string& body) const {
    return writeText(path, "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[" + roots + "]}]," +
                               body + json() + "}");
  }

 private:
  std::string json() const {
    std::string s = "\"buffers\":[{\"byteLength\":" + std::to_string(bytes_.size()) +
                    ",\"uri\":\"data:application/octet-stream;base64," + base64(bytes_) + "\"}],\"bufferViews\":[";
    for (std::size_t i = 0; i < views_.size(); ++i) s += (i ? "," : "") + views_[i];
    s += "],\"accessors\":[";
    for (std::size_t i = 0; i < accessors_.size(); ++i) s += (i ? "," : "") + accessors_[i];
    return s + "]";
  }
  static std::string num(float f) {
    char b[32];
    std::snprintf(b, sizeof b, "%.9g", double(f));
    return b;
  }
  std::string add(const void* data, std::size_t size, int componentType, int count, const char* type,
                  const std::string& extra) {
    while (bytes_.size() % 4) bytes_.push_back(0);
    const std::size_t offset = bytes_.size();
    bytes_.insert(bytes_.end(), static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + size);
    views_.push_back("{\"buffer\":0,\"byteOffset\":" + std::to_string(offset) + ",\"byteLength\":" + std::to_string(size) + "}");
    accessors_.push_back("{\"bufferView\":" + std::to_string(views_.size() - 1) + ",\"componentType\":" +
                         std::to_string(componentType) + ",\"count\":" + std::to_string(count) + ",\"type\":\"" + type +
                         "\"" + extra + "}");
    return std::to_string(accessors_.size() - 1);
  }
  std::vector<uint8_t> bytes_;
  std::vector<std::string> views_, accessors_;
};

// A quad skinned to two joints: joint "root" at the origin, joint "child" at (1,0,0). Vertices
// (0,0,0) and (0,1,0) follow the root, (1,0,0) the child, (1,1,0) both by half. The clip "bend"
// turns the child 90 degrees about z and lifts the root to z = 2 over one second. The skinned
// mesh's own node is moved by 100 in x, which glTF says to ignore.
fs::path writeSkinnedGltf(const fs::path& dir) {
  GltfData d;
  const std::string pos = d.floats({0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}, "VEC3", true);
  const std::string joints = d.ushorts({0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0}, "VEC4");
  const std::string weights = d.floats({1, 0, 0, 0, 1, 0, 0, 0, 0.5f, 0.5f, 0, 0, 1, 0, 0, 0}, "VEC4");
  const std::string idx = d.ushorts({0, 1, 2, 0, 2, 3}, "SCALAR");
  // Column-major inverse bind matrices: identity, and a translation by (-1,0,0).
  const std::string ibm = d.floats({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1,  //
                                    1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1},
                                   "MAT4");
  const std::string times = d.floats({0, 1}, "SCALAR");
  const float s = float(std::sqrt(0.5));
  const std::string rot = d.floats({0, 0, 0, 1, 0, 0, s, s}, "VEC4");
  const std::string lift = d.floats({0, 0, 0, 0, 0, 2}, "VEC3");
  const std::string body =
      "\"nodes\":[{\"name\":\"skinned\",\"mesh\":0,\"skin\":0,\"translation\":[100,0,0]},"
      "{\"name\":\"root\",\"children\":[2]},{\"name\":\"child\",\"translation\":[1,0,0]}],"
      "\"skins\":[{\"joints\":[1,2],\"inverseBindMatrices\":" + ibm + "}],"
      "\"meshes\":[{\"name\":\"quad\",\"primitives\":[{\"attributes\":{\"POSITION\":" + pos + ",\"JOINTS_0\":" + joints +
      ",\"WEIGHTS_0\":" + weights + "},\"indices\":" + idx + "}]}],"
      "\"animations\":[{\"name\":\"bend\",\"samplers\":[{\"input\":" + times + ",\"output\":" + rot +
      "},{\"input\":" + times + ",\"output\":" + lift + "}],"
      "\"channels\":[{\"sampler\":0,\"target\":{\"node\":2,\"path\":\"rotation\"}},"
      "{\"sampler\":1,\"target\":{\"node\":1,\"path\":\"translation\"}}]}],";
  return d.write(dir / "skinned.gltf", "0,1", body);
}

// `file` loaded at `fps` keyframes per second; the loader's warnings go to `warnings` when given.
anim::Animation loadAt(const fs::path& file, double fps, std::vector<std::string>* warnings = nullptr) {
  anim::LoadOptions options;
  options.fps = fps;
  if (warnings) options.warning = [warnings](const std::string& w) { warnings->push_back(w); };
  return anim::load(file.string(), options);
}

TEST(Gltf, SkinnedMeshIsBlendedFromItsJointsAsHandComputed) {
  const fs::path file = writeSkinnedGltf(tsah::test::scratchDir());
  const auto a = loadAt(file, 2);
  ASSERT_EQ(a.triangleCount(), 2u);
  ASSERT_EQ(a.vertexCount(), 4u);
  ASSERT_EQ(a.keyframeCount(), 3u);  // t = 0, 0.5, 1
  // t = 0: the bind pose.
  expectNear(vertexAt(a, 0, 2), {1, 1, 0}, "t=0 v2");
  // t = 1: root at z = 2, child turned 90 degrees: (1,1,0) by the child lands on (0,0,2), by the
  // root on (1,1,2); half of each.
  expectNear(vertexAt(a, 1, 0), {0, 0, 2}, "t=1 v0");
  expectNear(vertexAt(a, 1, 1), {1, 0, 2}, "t=1 v1");
  expectNear(vertexAt(a, 1, 2), {0.5, 0.5, 2}, "t=1 v2");
  expectNear(vertexAt(a, 1, 3), {0, 1, 2}, "t=1 v3");
  // t = .5: child turned 45 degrees (slerp), root at z = 1.
  const double h = std::sqrt(0.5);
  expectNear(vertexAt(a, 0.5, 2), {(1 + (1 - h)) / 2, (1 + h) / 2, 1}, "t=.5 v2");
  // Without a frame rate the clip's own key times are the keyframes.
  EXPECT_EQ(anim::load(file.string()).keyframeCount(), 2u);
}

// A triangle with two morph targets (v0 += (0,0,1), v2 += (0,2,0)) on a node at (5,0,0). Clip
// "morph" animates the weights from (0,0) to (1,0.5); clip "lift" moves the node up by 3 and leaves
// the weights at the mesh's defaults (0.25, 0).
fs::path writeMorphGltf(const fs::path& dir) {
  GltfData d;
  const std::string pos = d.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3", true);
  const std::string t0 = d.floats({0, 0, 1, 0, 0, 0, 0, 0, 0}, "VEC3", true);
  const std::string t1 = d.floats({0, 0, 0, 0, 0, 0, 0, 2, 0}, "VEC3", true);
  const std::string idx = d.ushorts({0, 1, 2}, "SCALAR");
  const std::string times = d.floats({0, 1}, "SCALAR");
  const std::string weights = d.floats({0, 0, 1, 0.5f}, "SCALAR");
  const std::string liftTimes = d.floats({0, 2}, "SCALAR");
  const std::string lift = d.floats({5, 0, 0, 5, 3, 0}, "VEC3");
  const std::string body =
      "\"nodes\":[{\"name\":\"blob\",\"mesh\":0,\"translation\":[5,0,0]}],"
      "\"meshes\":[{\"name\":\"tri\",\"weights\":[0.25,0],\"primitives\":[{\"attributes\":{\"POSITION\":" + pos +
      "},\"indices\":" + idx + ",\"targets\":[{\"POSITION\":" + t0 + "},{\"POSITION\":" + t1 + "}]}]}],"
      "\"animations\":[{\"name\":\"morph\",\"samplers\":[{\"input\":" + times + ",\"output\":" + weights +
      "}],\"channels\":[{\"sampler\":0,\"target\":{\"node\":0,\"path\":\"weights\"}}]},"
      "{\"name\":\"lift\",\"samplers\":[{\"input\":" + liftTimes + ",\"output\":" + lift +
      "}],\"channels\":[{\"sampler\":0,\"target\":{\"node\":0,\"path\":\"translation\"}}]}],";
  return d.write(dir / "morph.gltf", "0", body);
}

TEST(Gltf, MorphTargetWeightsAreInterpolatedAndBlended) {
  std::vector<std::string> warnings;
  const auto a = loadAt(writeMorphGltf(tsah::test::scratchDir()), 2, &warnings);
  ASSERT_EQ(a.keyframeCount(), 3u);
  expectNear(vertexAt(a, 0, 0), {5, 0, 0}, "t=0 v0");
  expectNear(vertexAt(a, 0.5, 0), {5, 0, 0.5}, "t=.5 v0");  // weights (0.5, 0.25)
  expectNear(vertexAt(a, 0.5, 2), {5, 1.5, 0}, "t=.5 v2");
  expectNear(vertexAt(a, 1, 2), {5, 2, 0}, "t=1 v2");
  ASSERT_EQ(warnings.size(), 1u);  // two clips, the first baked
  EXPECT_NE(warnings[0].find("baked clip 'morph' of 2"), std::string::npos) << warnings[0];
}

TEST(Gltf, ClipsAreChosenByNameOrIndex) {
  const fs::path file = writeMorphGltf(tsah::test::scratchDir());
  EXPECT_EQ(anim::modelClips(file.string()), (std::vector<std::string>{"morph", "lift"}));
  anim::LoadOptions options;
  options.clip = "lift";
  options.fps = 1;
  const auto byName = anim::load(file.string(), options);
  ASSERT_EQ(byName.keyframeCount(), 3u);  // 2 seconds at 1 fps
  // The node moves up by 1.5 per second; the weights stay at their defaults (0.25, 0).
  expectNear(vertexAt(byName, 1, 0), {5, 1.5, 0.25}, "lift t=1 v0");
  options.clip = "1";
  const auto byIndex = anim::load(file.string(), options);
  EXPECT_EQ(byName.allPositions(), byIndex.allPositions());
  options.clip = "wave";
  EXPECT_TRUE(
      tsah::test::throwsFileError([&] { anim::load(file.string(), options); }, {"no clip 'wave' (clips: morph, lift)"}));
}

TEST(Gltf, BrokenFilesGiveImportErrorsNamingThem) {
  const fs::path dir = tsah::test::scratchDir();
  const fs::path garbage = writeText(dir / "garbage.gltf", "{\"asset\": {\"version\": \"2.0\"}, \"meshes\": [{\"primitives\": 7}]");
  EXPECT_TRUE(tsah::test::throwsFileError([&] { anim::load(garbage.string()); }, {"garbage.gltf"}));
  const fs::path empty = writeText(dir / "empty.gltf", "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"name\":\"n\"}]}");
  EXPECT_THROW(anim::load(empty.string()), tsah::FileError);
}

// ---- assimp-testmodels ----------------------------------------------------------------------------

// The model /usr/share/assimp/models/<relative>, loaded; none when assimp-testmodels is not installed.
std::optional<anim::Animation> testModel(const char* relative) {
  const fs::path p = fs::path("/usr/share/assimp/models") / relative;
  if (!fs::exists(p)) return std::nullopt;
  return anim::load(p.string());
}

// Largest distance between two vertices' trajectories' relative offsets: > 0 when the mesh deforms
// (is not one rigid motion of the first keyframe's shape, detected by changing edge lengths).
double maxEdgeLengthChange(const anim::Animation& a) {
  const auto idx = a.indices();
  double worst = 0.0;
  const auto first = a.keyframe(0);
  for (uint32_t k = 1; k < a.keyframeCount(); ++k) {
    const auto p = a.keyframe(k);
    for (std::size_t t = 0; t < idx.size(); t += 3)
      for (int e = 0; e < 3; ++e) {
        const uint32_t u = idx[t + e], v = idx[t + (e + 1) % 3];
        auto len = [&](std::span<const float> q) {
          const double dx = q[3 * u] - q[3 * v], dy = q[3 * u + 1] - q[3 * v + 1], dz = q[3 * u + 2] - q[3 * v + 2];
          return std::sqrt(dx * dx + dy * dy + dz * dz);
        };
        worst = std::max(worst, std::fabs(len(p) - len(first)));
      }
  }
  return worst;
}

TEST(AssimpModels, SkinnedFbxDeforms) {
  const auto a = testModel("FBX/huesitos.fbx");
  if (!a) GTEST_SKIP() << "assimp-testmodels not installed";
  EXPECT_EQ(a->triangleCount(), 120u);
  EXPECT_GT(a->keyframeCount(), 10u);
  EXPECT_GT(maxEdgeLengthChange(*a), 1.0);  // a skinned bend stretches edges; a rigid motion would not
}

TEST(AssimpModels, MorphCubeGltfChangesShape) {
  const auto a = testModel("glTF2/glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf");
  if (!a) GTEST_SKIP() << "assimp-testmodels not installed";
  EXPECT_EQ(a->triangleCount(), 12u);
  EXPECT_EQ(a->vertexCount(), 8u);  // 24 split vertices welded into the cube's 8 corners
  EXPECT_GT(maxEdgeLengthChange(*a), 0.1);
}

TEST(AssimpModels, ColladaNodeAnimationMovesTheBox) {
  const auto a = testModel("Collada/box_nested_animation.dae");
  if (!a) GTEST_SKIP() << "assimp-testmodels not installed";
  EXPECT_EQ(a->triangleCount(), 12u);
  EXPECT_GT(a->keyframeCount(), 2u);
  const auto b0 = a->keyframeBounds(0), b1 = a->keyframeBounds(a->keyframeCount() - 1);
  EXPECT_NE(b0.min, b1.min);
}

}  // namespace
