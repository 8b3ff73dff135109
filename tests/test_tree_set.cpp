// Tree sets (.tbvh version 2): round trips, version 1 files read as a set of one, rejection of
// corrupt or inconsistent sets with one line naming the file, and the CPU runtime switching to the
// tree of each frame's part (boundaries and overlaps included).
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "tsah/base/binary_io.hpp"
#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "test_support.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/optimize/leaf_collapser.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/io/tree_set.hpp"

namespace {

using tsah::TimeRange;

struct Fixture {
  tsah::test::MovingTriangles scene = tsah::test::randomMovingTriangles(300, 4, 21, 2.0f);
  std::vector<tsah::Bvh> trees;  // tree s: sweep SAH on frame s, collapsed to leaves of <= 4
  std::vector<tsah::BvhBuildInfo> builds;

  explicit Fixture(uint32_t count) {
    const tsah::PrimitiveBoxes boxes = scene.boxes();
    tsah::LeafCollapser::Config l;
    l.maxLeafSize = 4;
    for (uint32_t s = 0; s < count; ++s) {
      trees.push_back(tsah::LeafCollapser(l).collapse(tsah::SweepSahBuilder().build(boxes.frame(s % boxes.frameCount))));
      tsah::BvhBuildInfo b;
      b.method = "sah0";
      b.selection = "none";
      b.seed = 40 + s;
      b.vertexCount = 900;
      b.topologyHash = tsah::topologyHash(scene.indices);
      builds.push_back(b);
    }
  }
};

std::vector<uint8_t> withCrc(std::vector<uint8_t> bytes) {
  const uint32_t crc = tsah::crc32(bytes.data(), bytes.size() - 4);
  std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
  return bytes;
}

template <typename T>
std::vector<uint8_t> patched(std::vector<uint8_t> bytes, std::size_t offset, T value) {
  std::memcpy(bytes.data() + offset, &value, sizeof value);
  return withCrc(std::move(bytes));
}

// The error must be one line that names the file.
void expectRefused(const std::vector<uint8_t>& bytes, const std::string& what) {
  try {
    tsah::decodeTreeSetFile(bytes, "set.tbvh");
    ADD_FAILURE() << "accepted: " << what;
  } catch (const tsah::FileError& e) {
    const std::string message = e.what();
    EXPECT_EQ(message.rfind("set.tbvh", 0), 0u) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
  }
}

TEST(TreeSet, RoundTripKeepsTreesRangesAndSegmentationInfo) {
  Fixture fx(3);
  const std::vector<TimeRange> ranges = {{0.0, 1.25}, {0.75, 2.25}, {1.75, 3.0}};  // overlaps of 0.5
  tsah::TreeSetInfo info;
  info.segmentation = "budget";
  info.overlap = 0.5;
  info.budget = 1.05;
  info.budgetRelative = true;
  const std::vector<uint8_t> bytes = tsah::encodeTreeSetFile(fx.trees, fx.builds, ranges, info);
  const tsah::TreeSet set = tsah::decodeTreeSetFile(bytes, "set.tbvh");
  EXPECT_EQ(set.version, 2u);
  ASSERT_EQ(set.size(), 3u);
  EXPECT_EQ(set.ranges, ranges);
  EXPECT_EQ(set.info.segmentation, "budget");
  EXPECT_EQ(set.info.overlap, 0.5);
  EXPECT_EQ(set.info.budget, 1.05);
  EXPECT_TRUE(set.info.budgetRelative);
  for (uint32_t s = 0; s < 3; ++s) {
    const tsah::FlatBvh expected = tsah::flattenBvh(fx.trees[s]);
    EXPECT_EQ(set.trees[s].triIndex, expected.triIndex);
    ASSERT_EQ(set.trees[s].nodes.size(), expected.nodes.size());
    EXPECT_EQ(std::memcmp(set.trees[s].nodes.data(), expected.nodes.data(), expected.nodes.size() * 64), 0);
    EXPECT_EQ(set.builds[s].seed, 40u + s);
    EXPECT_EQ(set.builds[s].timeStart, ranges[s].start);
    EXPECT_EQ(set.builds[s].timeEnd, ranges[s].end);
  }
  // Every tree starts 16-byte aligned (so its nodes are aligned in a mapped file).
  uint64_t offset;
  for (uint32_t s = 0; s < 3; ++s) {
    std::memcpy(&offset, bytes.data() + tsah::kTbvhSetHeaderBytes + 32 * s + 16, 8);
    EXPECT_EQ(offset % 16, 0u);
  }
  // Encoding is deterministic: the same set gives the same bytes.
  EXPECT_EQ(tsah::encodeTreeSetFile(fx.trees, fx.builds, ranges, info), bytes);
}

TEST(TreeSet, VersionOneFileIsASetOfOneTreeAndTheSingleTreeReaderRefusesSets) {
  Fixture fx(2);
  tsah::BvhBuildInfo b = fx.builds[0];
  b.timeStart = 2.0;
  b.timeEnd = 7.0;
  const std::vector<uint8_t> v1 = tsah::encodeBvhFile(fx.trees[0], b);
  const tsah::TreeSet set = tsah::decodeTreeSetFile(v1, "one.tbvh");
  EXPECT_EQ(set.version, 1u);
  ASSERT_EQ(set.size(), 1u);
  EXPECT_EQ(set.ranges[0], (TimeRange{2.0, 7.0}));
  EXPECT_EQ(set.info.segmentation, "single");
  EXPECT_EQ(set.treeAt(-100.0), 0u);
  EXPECT_EQ(set.treeAt(100.0), 0u);
  const std::vector<uint8_t> v2 =
      tsah::encodeTreeSetFile(fx.trees, fx.builds, std::vector<TimeRange>{{0, 1}, {1, 2}}, {});
  try {
    tsah::decodeFlatBvhFile(v2, "set.tbvh");
    ADD_FAILURE() << "the single-tree reader accepted a set";
  } catch (const tsah::FileError& e) {
    EXPECT_NE(std::string(e.what()).find("tree set"), std::string::npos) << e.what();
  }
}

TEST(TreeSet, WriterRefusesInconsistentSets) {
  Fixture fx(2);
  const std::vector<TimeRange> good = {{0, 1}, {1, 2}};
  EXPECT_THROW(tsah::encodeTreeSetFile(fx.trees, fx.builds, std::vector<TimeRange>{{0, 1}, {1.5, 2}}, {}),
               tsah::DataError);
  EXPECT_THROW(tsah::encodeTreeSetFile(fx.trees, fx.builds, std::vector<TimeRange>{{0, 1}}, {}), tsah::DataError);
  auto builds = fx.builds;
  builds[1].topologyHash ^= 1;
  EXPECT_THROW(tsah::encodeTreeSetFile(fx.trees, builds, good, {}), tsah::DataError);
  tsah::TreeSetInfo info;
  info.segmentation = "a-name-far-too-long";
  EXPECT_THROW(tsah::encodeTreeSetFile(fx.trees, fx.builds, good, info), tsah::ConfigError);
}

TEST(TreeSet, CorruptOrInconsistentSetsAreRefusedWithOneLine) {
  Fixture fx(3);
  const std::vector<TimeRange> ranges = {{0, 1}, {1, 2}, {2, 3}};
  const std::vector<uint8_t> bytes = tsah::encodeTreeSetFile(fx.trees, fx.builds, ranges, {});
  // Any flipped byte breaks the checksum (or a check before it); any truncation is refused.
  std::mt19937 rng(5);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<uint8_t> b = bytes;
    b[rng() % b.size()] ^= static_cast<uint8_t>(1 + rng() % 255);
    expectRefused(b, "flipped byte");
  }
  // With the set's checksum repaired, a flipped byte reaches the structural checks: the file is
  // refused with one line or (a change in an informative field) read as a valid set; nothing else.
  for (int trial = 0; trial < 400; ++trial) {
    std::vector<uint8_t> b = bytes;
    const std::size_t at = trial % 2 ? rng() % (tsah::kTbvhSetHeaderBytes + 32 * 3 + 16) : rng() % (b.size() - 4);
    b[at] ^= static_cast<uint8_t>(1 + rng() % 255);
    b = withCrc(std::move(b));
    try {
      const tsah::TreeSet set = tsah::decodeTreeSetFile(b, "set.tbvh");
      EXPECT_FALSE(tsah::validateTimeRanges(set.ranges).has_value()) << "byte " << at;
      for (const tsah::FlatBvh& t : set.trees) EXPECT_FALSE(tsah::validateFlatBvh(t).has_value()) << "byte " << at;
    } catch (const tsah::FileError& e) {
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
    }
  }
  for (std::size_t size : {std::size_t(0), std::size_t(7), std::size_t(95), bytes.size() / 2, bytes.size() - 1})
    expectRefused(std::vector<uint8_t>(bytes.begin(), bytes.begin() + size), "truncated");
  // Hostile or inconsistent fields with a valid checksum.
  expectRefused(patched(bytes, 8, uint32_t{3}), "unknown version");
  expectRefused(patched(bytes, 20, uint32_t{0}), "no trees");
  expectRefused(patched(bytes, 20, uint32_t{0x7fffffff}), "huge tree count");
  expectRefused(patched(bytes, 20, uint32_t{2}), "tree count too small for the table");
  expectRefused(patched(bytes, 28, uint32_t{123}), "vertex count differs from the trees'");
  expectRefused(patched(bytes, 32, uint32_t{0xdeadbeef}), "topology hash differs");
  expectRefused(patched(bytes, 36, uint32_t{4}), "unknown flag");
  expectRefused(patched(bytes, 48, 2.5), "set range not covered");
  expectRefused(patched(bytes, 56, -1.0), "negative overlap");
  const std::size_t entry1 = tsah::kTbvhSetHeaderBytes + 32;
  expectRefused(patched(bytes, entry1, 1.5), "gap between ranges (table and tree disagree too)");
  expectRefused(patched(bytes, entry1 + 8, 0.5), "unsorted ends");
  expectRefused(patched(bytes, entry1 + 16, uint64_t{1} << 40), "offset beyond the file");
  expectRefused(patched(bytes, entry1 + 24, uint64_t{100}), "tree size too small");
  // Range in the table that disagrees with the tree's own header (both sorted and covering).
  std::vector<TimeRange> shifted = {{0, 1.5}, {1.5, 2}, {2, 3}};
  const std::vector<uint8_t> other = tsah::encodeTreeSetFile(fx.trees, fx.builds, shifted, {});
  expectRefused(patched(other, entry1 - 32 + 8, 1.6), "table range vs tree header");
  // A tree from another animation inside an otherwise consistent set (its own checksum valid).
  auto mixed = fx.builds;
  for (auto& b : mixed) b.topologyHash ^= 7u;
  std::vector<uint8_t> foreign = tsah::encodeTreeSetFile(fx.trees, mixed, ranges, {});
  std::vector<uint8_t> spliced = bytes;
  uint64_t offset0, size0;
  std::memcpy(&offset0, bytes.data() + tsah::kTbvhSetHeaderBytes + 16, 8);
  std::memcpy(&size0, bytes.data() + tsah::kTbvhSetHeaderBytes + 24, 8);
  std::memcpy(spliced.data() + offset0, foreign.data() + offset0, size0);
  expectRefused(withCrc(spliced), "a tree of another animation");
  // Non-zero padding between trees.
  uint64_t offset1;
  std::memcpy(&offset1, bytes.data() + entry1 + 16, 8);
  if (offset0 + size0 < offset1) {
    std::vector<uint8_t> padded = bytes;
    padded[offset1 - 1] = 1;
    expectRefused(withCrc(padded), "padding");
  }
}

TEST(TreeSet, FileHelpersRoundTripAndNameTheFileOnError) {
  Fixture fx(2);
  const auto dir = tsah::test::scratchDir();
  const std::string path = (dir / "set.tbvh").string();
  tsah::saveTreeSetFile(path, fx.trees, fx.builds, std::vector<TimeRange>{{0, 1}, {1, 2}}, {});
  EXPECT_EQ(tsah::loadTreeSetFile(path).size(), 2u);
  std::vector<uint8_t> bytes = tsah::readFile(path);
  bytes[bytes.size() / 2] ^= 0x40;
  tsah::writeFileAtomically(path, bytes);
  try {
    tsah::loadTreeSetFile(path);
    ADD_FAILURE() << "corrupt set accepted";
  } catch (const tsah::FileError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(path, 0), 0u) << e.what();
  }
}

// The CPU runtime refits and traces the tree of each frame's part: compare its refitted tree with a
// runtime made from that tree alone, at times on and around the boundaries and in an overlap.
TEST(TreeSet, CpuRuntimeSwitchesToTheTreeOfEachFramesPart) {
  Fixture fx(3);
  const std::vector<TimeRange> ranges = {{0.0, 1.2}, {0.8, 2.0}, {2.0, 3.0}};  // switch at 1.0 and 2.0
  const tsah::TreeSet set =
      tsah::decodeTreeSetFile(tsah::encodeTreeSetFile(fx.trees, fx.builds, ranges, {}), "set.tbvh");
  tsah::CpuRuntime runtime(set, fx.scene.indices, 900, {2});
  EXPECT_EQ(runtime.treeCount(), 3u);
  std::vector<std::unique_ptr<tsah::CpuRuntime>> alone;
  for (const tsah::FlatBvh& tree : set.trees)
    alone.push_back(std::make_unique<tsah::CpuRuntime>(tree, fx.scene.indices, 900, tsah::CpuRuntime::Config{2}));
  const std::size_t perFrame = 900 * 3;
  const struct {
    double time;
    uint32_t tree;
  } cases[] = {{0.0, 0}, {0.9, 0}, {std::nextafter(1.0, 0.0), 0}, {1.0, 1}, {1.1, 1}, {1.99, 1},
               {2.0, 2},  {3.0, 2}, {-1.0, 0},                     {9.0, 2}, {0.5, 0}};
  for (const auto& c : cases) {
    EXPECT_EQ(runtime.selectTreeAt(c.time), c.tree) << "time " << c.time;
    EXPECT_EQ(runtime.currentTree(), c.tree);
    const uint32_t frame = static_cast<uint32_t>(std::clamp(c.time, 0.0, 3.0));
    const std::span<const float> positions(fx.scene.positions.data() + frame * perFrame, perFrame);
    runtime.update(positions);
    alone[c.tree]->update(positions);
    const tsah::FlatBvh& got = runtime.tree();
    const tsah::FlatBvh& want = alone[c.tree]->tree();
    EXPECT_EQ(got.triIndex, want.triIndex) << "time " << c.time;
    ASSERT_EQ(got.nodes.size(), want.nodes.size()) << "time " << c.time;
    EXPECT_EQ(std::memcmp(got.nodes.data(), want.nodes.data(), got.nodes.size() * sizeof(tsah::GpuBvhNode)), 0);
    ASSERT_EQ(runtime.woop().size(), alone[c.tree]->woop().size());
    EXPECT_EQ(std::memcmp(runtime.woop().data(), alone[c.tree]->woop().data(), runtime.woop().size_bytes()), 0);
  }
  // A runtime made from one tree keeps it whatever the time.
  EXPECT_EQ(alone[1]->selectTreeAt(0.0), 0u);
  EXPECT_EQ(alone[1]->tree().triIndex, set.trees[1].triIndex);
}

}  // namespace
