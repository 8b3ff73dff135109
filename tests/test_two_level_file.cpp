// The two-level .tbvh file (version 3, docs/tbvh-format.md): round trip, corrupt input, the
// other versions' readers, and a file read with a scene it was not built for.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>

#include "anim/scene.hpp"
#include "anim/tanim.hpp"
#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "tsah/base/files.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/io/two_level_file.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "test_support.hpp"

namespace fs = std::filesystem;

namespace {

// The two structures' runtimes at scene time t give the same closest hits on a grid of rays from above.
void expectSameHits(const tsah::TwoLevelScene& built, const tsah::TwoLevelScene& read, double t) {
  tsah::TwoLevelRuntime a(built), b(read);
  a.update(t);
  b.update(t);
  for (int i = 0; i < 64; ++i) {
    tsah::Ray ray;
    ray.org = {0.1f * float(i % 8) - 0.3f, 8.0f, 0.1f * float(i / 8) - 0.3f};
    ray.dir = {0.05f, -1.0f, 0.02f};
    ray.tmin = 0.0f;
    ray.tmax = 100.0f;
    const tsah::TwoLevelHit ha = a.closestHit(ray), hb = b.closestHit(ray);
    EXPECT_EQ(ha.instance, hb.instance);
    EXPECT_EQ(ha.prim, hb.prim);
    EXPECT_EQ(ha.t, hb.t);
  }
}

using tsah::test::writeText;

// A static source twice (one mirrored), an animated one with two offsets and a keyed path.
fs::path writeScene(const fs::path& dir, const std::string& name, const std::string& secondOffset = "1.5") {
  const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 200, 6, 5);
  anim::saveTanim(wave, (dir / "wave.tanim").string());
  writeText(dir / "tri.obj", "v 1 0 0\nv 0 1 0\nv 0 0 1\nv 2 0 0\nf 1 2 3\nf 2 3 4\n");
  writeText(dir / name, R"({"fps": 2, "objects": [
    {"file": "tri.obj", "instances": [{}, {"transform": {"translate": [3, 0, 0], "scale": [-1, 2, 1]}}]},
    {"file": "wave.tanim", "instances": [{"transform": {"rotate": [0, 30, 0]}},
      {"offset": )" + secondOffset + R"(, "path": [{"time": 0}, {"time": 6, "translate": [0, 4, 0]}]}]}]})");
  return dir / name;
}

tsah::TreeOptions options() {
  tsah::TreeOptions o;
  o.frames = 3;
  o.objective.k = 1;
  o.objective.maxLeafSize = 2;
  o.threads = 1;
  return o;
}

// The bytes with their trailing checksum recomputed (to reach the checks behind it).
std::vector<uint8_t> withCrc(std::vector<uint8_t> bytes) {
  const uint32_t crc = tsah::crc32(bytes.data(), bytes.size() - 4);
  std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
  return bytes;
}

template <class T>
void put(std::vector<uint8_t>& bytes, std::size_t offset, T value) {
  std::memcpy(bytes.data() + offset, &value, sizeof value);
}

std::string decodeError(const std::vector<uint8_t>& bytes) {
  try {
    tsah::decodeTwoLevelFile(bytes, "x.tbvh");
  } catch (const tsah::FileError& e) {
    return e.what();
  }
  return "";
}

class TwoLevelFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = tsah::test::scratchDir();
    scenePath = writeScene(dir, "scene.json");
    built = std::make_unique<tsah::TwoLevelScene>(tsah::loadTwoLevelScene(scenePath.string(), {}, options()));
    bytes = tsah::encodeTwoLevelScene(*built);
  }
  fs::path dir, scenePath;
  std::unique_ptr<tsah::TwoLevelScene> built;
  std::vector<uint8_t> bytes;
};

TEST_F(TwoLevelFile, RoundTripKeepsEveryTreeAndTracesTheSame) {
  const fs::path tree = dir / "scene.tbvh";
  tsah::saveTwoLevelScene(tree.string(), *built);
  const tsah::TwoLevelScene read = tsah::loadTwoLevelSceneFile(tree.string(), anim::loadSceneSources(scenePath.string()));
  ASSERT_EQ(read.blases.size(), built->blases.size());
  for (std::size_t b = 0; b < read.blases.size(); ++b) {
    EXPECT_EQ(read.blases[b].flat.nodes.size(), built->blases[b].flat.nodes.size());
    for (std::size_t n = 0; n < std::min(read.blases[b].flat.nodes.size(), built->blases[b].flat.nodes.size()); ++n)
      EXPECT_EQ(0, std::memcmp(&read.blases[b].flat.nodes[n], &built->blases[b].flat.nodes[n], sizeof(tsah::GpuBvhNode)));
    EXPECT_EQ(read.blases[b].flat.triIndex, built->blases[b].flat.triIndex);
    EXPECT_DOUBLE_EQ(read.blases[b].cost, built->blases[b].cost);
    EXPECT_EQ(read.blases[b].animated, built->blases[b].animated);
  }
  ASSERT_EQ(read.tlases.size(), built->tlases.size());
  for (std::size_t t = 0; t < read.tlases.size(); ++t) {
    EXPECT_EQ(read.tlases[t].bvh.primIds, built->tlases[t].bvh.primIds);
    EXPECT_EQ(read.tlases[t].bvh.frameCount, built->tlases[t].bvh.frameCount);
    EXPECT_EQ(read.tlases[t].range, built->tlases[t].range);
    EXPECT_EQ(read.tlases[t].firstFrame, built->tlases[t].firstFrame);
  }
  EXPECT_DOUBLE_EQ(read.tlasCost, built->tlasCost);
  EXPECT_EQ(read.objective, built->objective);
  EXPECT_EQ(read.instancePose, built->instancePose);
  EXPECT_EQ(read.poses.size(), 2u);
  // The same bytes again, and the same hits.
  EXPECT_EQ(tsah::encodeTwoLevelScene(read), tsah::readFile(tree.string()));
  expectSameHits(*built, read, 2.5);
}

TEST_F(TwoLevelFile, CorruptFilesAreRefusedWithOneLine) {
  EXPECT_EQ(decodeError(bytes), "");
  std::vector<uint8_t> flipped = bytes;
  flipped[100] ^= 0x10;
  EXPECT_NE(decodeError(flipped).find("checksum mismatch"), std::string::npos);
  EXPECT_NE(decodeError(std::vector<uint8_t>(bytes.begin(), bytes.begin() + 200)).find("too small"), std::string::npos);
  // Header fields (offsets: docs/tbvh-format.md, version 3).
  struct Case {
    std::size_t offset;
    uint32_t value;
    const char* expected;
  };
  const uint32_t instances = uint32_t(built->instanceCount());
  const std::size_t poseTable = 64 + 8 * std::size_t(instances);
  for (const Case& c : std::vector<Case>{
           {12, 65, "header size is not 64"},
           {16, 0, "BLAS count 0"},
           {16, 1u << 30, "BLAS count 1073741824"},
           {16, 3, "BLAS 0 starts at byte"},
           {20, 0, "instance count 0"},
           {24, 100, "pose count 100 exceeds"},
           {28, 0x80000000u, "flattened object count 2147483648 exceeds"},
           {28, 100000, "too small"},
           {60, 1, "reserved header words"},
           {64, 7, "instance 0 names BLAS 7 of 2"},
           {64 + 4, 0, "instance 0's pose belongs to another BLAS"},
           {64 + 8 * 2 + 4, 0xffffffffu, "the instances of BLAS 1 are posed and unposed"},
           {poseTable, 0, "instance 2's pose belongs to another BLAS"},
           {poseTable + 4, 2, "unknown outside mode 2"},
       }) {
    std::vector<uint8_t> bad = bytes;
    put(bad, c.offset, c.value);
    const std::string message = decodeError(withCrc(bad));
    EXPECT_NE(message.find(c.expected), std::string::npos) << "offset " << c.offset << ": " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos);
  }
  std::vector<uint8_t> badSpeed = bytes;
  put(badSpeed, poseTable + 16, -1.0);
  EXPECT_NE(decodeError(withCrc(badSpeed)).find("speed"), std::string::npos);
  const std::size_t treeTable = poseTable + 24 * built->poses.size();
  std::vector<uint8_t> badOffset = bytes;
  put(badOffset, treeTable, uint64_t(8));
  EXPECT_NE(decodeError(withCrc(badOffset)).find("BLAS 0 starts at byte 8"), std::string::npos);
  std::vector<uint8_t> badTime = bytes;
  put(badTime, 40, -1.0);  // time end before time start
  EXPECT_NE(decodeError(withCrc(badTime)).find("time range"), std::string::npos);
  // A BLAS image whose own checksum breaks: named by the inner reader.
  uint64_t firstTree;
  std::memcpy(&firstTree, bytes.data() + treeTable, 8);
  std::vector<uint8_t> badTree = bytes;
  badTree[firstTree + 170] ^= 1;
  EXPECT_NE(decodeError(withCrc(badTree)).find("(BLAS 0)"), std::string::npos) << decodeError(withCrc(badTree));
}

// A structure of several TLAS trees (one per part of the scene's time): the header's TLAS count,
// every tree round-tripped, and broken counts and ranges refused.
TEST_F(TwoLevelFile, TlasTreesPerTimePartRoundTripAndBrokenRangesAreRefused) {
  tsah::TlasOptions tlas;
  tlas.trees = 3;
  const tsah::TwoLevelScene parts = tsah::loadTwoLevelScene(scenePath.string(), {}, options(), tlas);
  ASSERT_EQ(parts.tlases.size(), 3u);
  const std::vector<uint8_t> file = tsah::encodeTwoLevelScene(parts);
  uint32_t word;
  std::memcpy(&word, file.data() + 48, 4);
  EXPECT_EQ(word, 3u);
  std::memcpy(&word, bytes.data() + 48, 4);  // one TLAS: written 0, as before the count existed
  EXPECT_EQ(word, built->tlases.size() == 1 ? 0u : uint32_t(built->tlases.size()));
  const fs::path tree = dir / "parts.tbvh";
  tsah::saveTwoLevelScene(tree.string(), parts);
  const tsah::TwoLevelScene read = tsah::loadTwoLevelSceneFile(tree.string(), anim::loadSceneSources(scenePath.string()));
  ASSERT_EQ(read.tlases.size(), 3u);
  for (std::size_t t = 0; t < 3; ++t) {
    EXPECT_EQ(read.tlases[t].range, parts.tlases[t].range);
    EXPECT_EQ(read.tlases[t].firstFrame, parts.tlases[t].firstFrame);
    EXPECT_EQ(read.tlases[t].frameCount, parts.tlases[t].frameCount);
    EXPECT_EQ(read.tlases[t].bvh.primIds, parts.tlases[t].bvh.primIds);
  }
  EXPECT_EQ(read.tlasFrameCosts, parts.tlasFrameCosts);
  EXPECT_EQ(tsah::encodeTwoLevelScene(read), file);
  for (const double t : {0.0, 1.0, 2.0, 2.5, 4.0, 6.0})  // the parts switch at scene frames 2 and 4
    expectSameHits(parts, read, t);

  for (const auto& [value, expected] : std::vector<std::pair<uint32_t, std::string>>{
           {1, "TLAS count 1 is written 0"}, {5000, "TLAS count 5000 exceeds 4096"}, {2, "starts at byte"}}) {
    std::vector<uint8_t> bad = file;
    put(bad, 48, value);
    EXPECT_NE(decodeError(withCrc(bad)).find(expected), std::string::npos) << value << ": " << decodeError(withCrc(bad));
  }
  // The parts' ranges: touching, in order, covering the header's range.
  std::vector<tsah::BvhBuildInfo> builds;
  for (const tsah::TlasTree& t : parts.tlases) builds.push_back(t.info);
  EXPECT_EQ(tsah::validateTlasRanges(builds, parts.scene.start, parts.scene.end), std::nullopt);
  auto gap = builds;
  gap[1].timeStart += 0.25;
  EXPECT_NE(tsah::validateTlasRanges(gap, parts.scene.start, parts.scene.end)->find("TLAS 1 does not start where TLAS 0 ends"),
            std::string::npos);
  EXPECT_NE(tsah::validateTlasRanges(builds, parts.scene.start - 1.0, parts.scene.end)->find("TLAS 0 does not start"),
            std::string::npos);
  EXPECT_NE(tsah::validateTlasRanges(builds, parts.scene.start, parts.scene.end + 1.0)->find("the last TLAS does not end"),
            std::string::npos);
  auto empty = builds;
  empty[2].timeStart = empty[2].timeEnd = empty[1].timeEnd;
  EXPECT_NE(tsah::validateTlasRanges(empty, parts.scene.start, parts.scene.end)->find("TLAS 2's time range"),
            std::string::npos);
  std::vector<tsah::Bvh> blasTrees, tlasTrees;
  for (const tsah::Blas& b : parts.blases) blasTrees.push_back(b.bvh);
  std::vector<tsah::BvhBuildInfo> blasBuilds;
  for (const tsah::Blas& b : parts.blases) blasBuilds.push_back(b.info);
  for (const tsah::TlasTree& t : parts.tlases) tlasTrees.push_back(t.bvh);
  std::vector<uint32_t> instanceBlas, instancePose;
  for (uint32_t i = 0; i < parts.instanceCount(); ++i) {
    instanceBlas.push_back(parts.scene.instances[i].source);
    instancePose.push_back(parts.instancePose[i] == tsah::kInvalidIndex ? tsah::kTbvhNoPose : parts.instancePose[i]);
  }
  std::vector<tsah::TwoLevelPoseRecord> poses;
  for (const tsah::Pose& p : parts.poses) poses.push_back({p.blas, 0, p.time.offset, p.time.speed});
  EXPECT_THROW(tsah::encodeTwoLevelFile(blasTrees, blasBuilds, tlasTrees, gap, instanceBlas, instancePose, poses),
               tsah::DataError);
  EXPECT_EQ(tsah::encodeTwoLevelFile(blasTrees, blasBuilds, tlasTrees, builds, instanceBlas, instancePose, poses), file);
  // No TLAS at all: refused before the header is written.
  try {
    tsah::encodeTwoLevelFile(blasTrees, blasBuilds, std::span<const tsah::Bvh>(), std::span<const tsah::BvhBuildInfo>(),
                             instanceBlas, instancePose, poses);
    ADD_FAILURE() << "a structure without a TLAS encoded";
  } catch (const tsah::DataError& e) {
    EXPECT_NE(std::string(e.what()).find("TLAS count 0 is not in 1..4096"), std::string::npos) << e.what();
  }
  // A file whose parts another scene's frames do not fill as stored is refused against that scene.
  const fs::path slower = dir / "slower.json";
  const std::vector<uint8_t> sceneBytes = tsah::readFile(scenePath.string());
  std::string text(sceneBytes.begin(), sceneBytes.end());
  text.replace(text.find("\"fps\": 2"), 8, "\"fps\": 4");
  tsah::test::writeText(slower, text);
  try {
    tsah::loadTwoLevelSceneFile(tree.string(), anim::loadSceneSources(slower.string()));
    ADD_FAILURE() << "a file read with a scene of other frames";
  } catch (const tsah::DataError& e) {
    EXPECT_NE(std::string(e.what()).find("TLAS 0 holds boxes for"), std::string::npos) << e.what();
  }
}

TEST_F(TwoLevelFile, OtherVersionsReadersPointToEachOther) {
  try {
    tsah::decodeTreeSetFile(bytes, "x.tbvh");
    ADD_FAILURE() << "a version 3 file read as a tree set";
  } catch (const tsah::FileError& e) {
    EXPECT_NE(std::string(e.what()).find("two-level scene (.tbvh version 3)"), std::string::npos) << e.what();
  }
  try {
    tsah::decodeFlatBvhFile(bytes, "x.tbvh");
    ADD_FAILURE() << "a version 3 file read as one tree";
  } catch (const tsah::FileError& e) {
    EXPECT_NE(std::string(e.what()).find("two-level scene (.tbvh version 3)"), std::string::npos) << e.what();
  }
  const std::vector<uint8_t> single = tsah::encodeBvhFile(built->blases[0].bvh, built->blases[0].info);
  EXPECT_NE(decodeError(single).find("is a .tbvh version 1 file, not a two-level scene"), std::string::npos);
}

TEST_F(TwoLevelFile, AFileReadWithAnotherSceneIsRefused) {
  const fs::path tree = dir / "scene.tbvh";
  tsah::saveTwoLevelScene(tree.string(), *built);
  const auto refused = [&](const fs::path& other, const std::string& part) {
    try {
      tsah::loadTwoLevelSceneFile(tree.string(), anim::loadSceneSources(other.string()));
    } catch (const tsah::DataError& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find(tree.string() + " was not built for " + other.string()), std::string::npos) << message;
      EXPECT_NE(message.find(part), std::string::npos) << message;
      return;
    }
    ADD_FAILURE() << other << " was accepted";
  };
  // Another time offset: another pose.
  refused(writeScene(dir, "offset.json", "2.5"), "poses differ");
  // Another mesh for the static source.
  writeText(dir / "other" / "tri.obj", "v 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n");
  fs::copy_file(dir / "wave.tanim", dir / "other" / "wave.tanim");
  fs::copy_file(dir / "scene.json", dir / "other" / "scene.json");
  refused(dir / "other" / "scene.json", "triangles");
  // A path moved far away: the stored TLAS boxes no longer hold the instance.
  std::string text = "";
  {
    const std::vector<uint8_t> raw = tsah::readFile(scenePath.string());
    text.assign(raw.begin(), raw.end());
  }
  text.replace(text.find("[0, 4, 0]"), 9, "[0, 400, 0]");
  writeText(dir / "moved.json", text);
  refused(dir / "moved.json", "TLAS boxes");
}

// Objects flattened into one source: the file records them, and reading it with its scene
// flattens the same objects before matching; their table is checked like the others.
TEST_F(TwoLevelFile, FlattenedObjectsRoundTripAndAreChecked) {
  const auto flattenedBuild = [&](const std::vector<uint32_t>& objects) {
    return tsah::buildTwoLevelScene(anim::flattenObjects(anim::loadSceneSources(scenePath.string()), objects), options());
  };
  const tsah::TwoLevelScene mixed = flattenedBuild({1});
  const fs::path tree = dir / "flattened.tbvh";
  tsah::saveTwoLevelScene(tree.string(), mixed);
  const tsah::TwoLevelScene read = tsah::loadTwoLevelSceneFile(tree.string(), anim::loadSceneSources(scenePath.string()));
  EXPECT_EQ(read.scene.flattenedObjects, (std::vector<uint32_t>{1}));
  ASSERT_EQ(read.instanceCount(), 3u);  // the static source's two instances and the merged one
  EXPECT_TRUE(read.blases[1].animated);
  EXPECT_EQ(tsah::encodeTwoLevelScene(read), tsah::readFile(tree.string()));
  expectSameHits(mixed, read, 1.5);
  // A file without the record (version 3 as before) is read with nothing flattened.
  EXPECT_TRUE(tsah::decodeTwoLevelFile(bytes, "x.tbvh").flattenedObjects.empty());

  // Both objects flattened: the table holds 0, 1 after the pose table (one pose: the merged source).
  const std::vector<uint8_t> both = tsah::encodeTwoLevelScene(flattenedBuild({0, 1}));
  const std::size_t table = 64 + 8 * 1 + 24 * 1;
  const auto withIds = [&](uint32_t first, uint32_t second) {
    std::vector<uint8_t> bad = both;
    put(bad, table, first);
    put(bad, table + 4, second);
    return withCrc(bad);
  };
  EXPECT_EQ(decodeError(withIds(0, 1)), "");
  EXPECT_NE(decodeError(withIds(1, 1)).find("flattened object 1 follows 1 (the ids must be increasing, without duplicates)"),
            std::string::npos);
  EXPECT_NE(decodeError(withIds(1, 0)).find("flattened object 0 follows 1"), std::string::npos);
  // An id the scene does not have: refused against the scene, naming both files.
  tsah::writeFileAtomically(tree.string(), withIds(0, 5));
  try {
    tsah::loadTwoLevelSceneFile(tree.string(), anim::loadSceneSources(scenePath.string()));
    ADD_FAILURE() << "object 5 accepted";
  } catch (const tsah::DataError& e) {
    EXPECT_NE(std::string(e.what()).find(tree.string() + " was not built for " + scenePath.string() +
                                         ": it flattens object 5, the scene has 2 objects"),
              std::string::npos)
        << e.what();
  }
  // The encoder refuses what the reader would.
  std::vector<tsah::Bvh> trees{mixed.blases[0].bvh, mixed.blases[1].bvh};
  std::vector<tsah::BvhBuildInfo> builds{mixed.blases[0].info, mixed.blases[1].info};
  std::vector<tsah::Bvh> tlases{mixed.tlases[0].bvh};
  std::vector<tsah::BvhBuildInfo> tlasBuilds{mixed.tlases[0].info};
  EXPECT_THROW(tsah::encodeTwoLevelFile(trees, builds, tlases, tlasBuilds, std::vector<uint32_t>{0, 0, 1},
                                        std::vector<uint32_t>{tsah::kTbvhNoPose, tsah::kTbvhNoPose, 0},
                                        std::vector<tsah::TwoLevelPoseRecord>{{1, 0, 0.0, 1.0}}, std::vector<uint32_t>{1, 1}),
               tsah::DataError);
}

}  // namespace
