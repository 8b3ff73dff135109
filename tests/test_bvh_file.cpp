// The .tbvh format: round trips, canonical order, and rejection of corrupt or hostile files.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <numeric>
#include <random>

#include "tsah/base/binary_io.hpp"
#include "tsah/base/error.hpp"
#include "test_support.hpp"
#include "tsah/io/bvh_file.hpp"

namespace {

using tsah::Aabb;
using tsah::Bvh;
using tsah::BvhNode;

// A random binary tree over `prims` primitives with leaves of 1..maxLeaf primitives, nodes in
// shuffled index order (so the writer has to canonicalize), random boxes for `frames` frames.
Bvh randomTree(uint32_t prims, uint32_t frames, uint32_t maxLeaf, std::mt19937& rng) {
  std::vector<uint32_t> ids(prims);
  std::iota(ids.begin(), ids.end(), 0u);
  std::shuffle(ids.begin(), ids.end(), rng);
  Bvh bvh;
  bvh.primIds = ids;
  // Build recursively over primId ranges, then shuffle node indices.
  struct Range {
    uint32_t node, begin, count;
  };
  bvh.nodes.push_back({});
  std::vector<Range> work{{0, 0, prims}};
  while (!work.empty()) {
    const Range r = work.back();
    work.pop_back();
    if (r.count <= maxLeaf && (r.count == 1 || rng() % 3 == 0)) {
      bvh.nodes[r.node].primBegin = r.begin;
      bvh.nodes[r.node].primCount = r.count;
      continue;
    }
    const uint32_t leftCount = 1 + static_cast<uint32_t>(rng() % (r.count - 1));
    const auto left = static_cast<uint32_t>(bvh.nodes.size());
    bvh.nodes.push_back({});
    bvh.nodes.push_back({});
    bvh.nodes[r.node].left = left;
    bvh.nodes[r.node].right = left + 1;
    bvh.nodes[left].parent = bvh.nodes[left + 1].parent = r.node;
    work.push_back({left, r.begin, leftCount});
    work.push_back({left + 1, r.begin + leftCount, r.count - leftCount});
  }
  // Shuffle node indices.
  std::vector<uint32_t> perm(bvh.nodes.size());
  std::iota(perm.begin(), perm.end(), 0u);
  std::shuffle(perm.begin(), perm.end(), rng);
  std::vector<BvhNode> shuffled(bvh.nodes.size());
  auto map = [&](uint32_t i) { return i == tsah::kInvalidIndex ? i : perm[i]; };
  for (std::size_t i = 0; i < bvh.nodes.size(); ++i) {
    BvhNode n = bvh.nodes[i];
    n.parent = map(n.parent);
    if (!n.isLeaf()) {
      n.left = map(n.left);
      n.right = map(n.right);
    }
    shuffled[perm[i]] = n;
  }
  bvh.nodes = std::move(shuffled);
  bvh.root = perm[0];

  std::uniform_real_distribution<float> coord(-10.0f, 10.0f), size(0.0f, 1.0f);
  tsah::PrimitiveBoxes boxes;
  boxes.frameCount = frames;
  boxes.primCount = prims;
  for (uint32_t i = 0; i < frames * prims; ++i) {
    Aabb b;
    const tsah::Vec3 p{coord(rng), coord(rng), coord(rng)};
    b.extend(p);
    b.extend(p + tsah::Vec3{size(rng), size(rng), size(rng)});
    boxes.boxes.push_back(b);
  }
  tsah::refit(bvh, boxes);
  return bvh;
}

tsah::BvhBuildInfo sampleInfo(uint32_t prims) {
  tsah::BvhBuildInfo info;
  info.method = "tsah";
  info.selection = "mh";
  info.objective.k = 1;
  info.representativeFrames = 5;
  info.seed = 0x123456789abcdefull;
  info.objective.cost.ct = 3.0f;
  info.objective.cost.ci = 2.0f;
  info.objective.maxLeafSize = 8;
  info.buildSeconds = 1.25;
  info.timeStart = 0.5;
  info.timeEnd = 47.0;
  info.triangleCount = prims;
  info.vertexCount = 3 * prims;
  info.topologyHash = 0xdeadbeef;
  return info;
}

// Two trees are the same when they have the same shape, the same primitives in each leaf, in
// the same order, and bit-identical boxes, node numbering aside.
void expectSameTree(const Bvh& a, const Bvh& b) {
  ASSERT_EQ(a.frameCount, b.frameCount);
  ASSERT_EQ(a.nodeCount(), b.nodeCount());
  ASSERT_EQ(a.primCount(), b.primCount());
  std::vector<std::pair<uint32_t, uint32_t>> stack{{a.root, b.root}};
  while (!stack.empty()) {
    auto [na, nb] = stack.back();
    stack.pop_back();
    for (uint32_t f = 0; f < a.frameCount; ++f)
      ASSERT_EQ(0, std::memcmp(&a.box(na, f), &b.box(nb, f), sizeof(Aabb)));
    const BvhNode& x = a.nodes[na];
    const BvhNode& y = b.nodes[nb];
    ASSERT_EQ(x.isLeaf(), y.isLeaf());
    if (x.isLeaf()) {
      ASSERT_EQ(x.primCount, y.primCount);
      for (uint32_t i = 0; i < x.primCount; ++i)
        ASSERT_EQ(a.primIds[x.primBegin + i], b.primIds[y.primBegin + i]);
    } else {
      stack.push_back({x.left, y.left});
      stack.push_back({x.right, y.right});
    }
  }
}

TEST(BvhFile, RoundTripIsBitExactAndKeepsTheTree) {
  std::mt19937 rng(7);
  for (uint32_t prims : {1u, 2u, 3u, 17u, 500u}) {
    for (uint32_t frames : {1u, 5u}) {
      const Bvh bvh = randomTree(prims, frames, 8, rng);
      ASSERT_FALSE(tsah::validate(bvh));
      const auto info = sampleInfo(prims);
      const auto bytes = tsah::encodeBvhFile(bvh, info);
      const tsah::BvhFile file = tsah::decodeBvhFile(bytes, "mem.tbvh");
      EXPECT_FALSE(tsah::validate(file.bvh)) << *tsah::validate(file.bvh);
      expectSameTree(bvh, file.bvh);
      EXPECT_EQ(file.info.method, info.method);
      EXPECT_EQ(file.info.selection, info.selection);
      EXPECT_EQ(file.info.objective.k, info.objective.k);
      EXPECT_EQ(file.info.representativeFrames, info.representativeFrames);
      EXPECT_EQ(file.info.seed, info.seed);
      EXPECT_EQ(file.info.objective.cost.ct, info.objective.cost.ct);
      EXPECT_EQ(file.info.objective.cost.ci, info.objective.cost.ci);
      EXPECT_EQ(file.info.objective.maxLeafSize, info.objective.maxLeafSize);
      EXPECT_EQ(file.info.buildSeconds, info.buildSeconds);
      EXPECT_EQ(file.info.timeStart, info.timeStart);
      EXPECT_EQ(file.info.timeEnd, info.timeEnd);
      EXPECT_EQ(file.info.triangleCount, prims);
      EXPECT_EQ(file.info.vertexCount, info.vertexCount);
      EXPECT_EQ(file.info.topologyHash, info.topologyHash);
      // Re-encoding the decoded tree gives the same bytes: the layout is canonical.
      EXPECT_EQ(tsah::encodeBvhFile(file.bvh, file.info), bytes);
    }
  }
}

TEST(BvhFile, FlatFormIsCanonicalPreOrder) {
  std::mt19937 rng(11);
  const Bvh bvh = randomTree(300, 2, 4, rng);
  const tsah::FlatBvh flat = tsah::flattenBvh(bvh);
  ASSERT_FALSE(tsah::validateFlatBvh(flat));
  EXPECT_EQ(flat.leafCount, flat.interiorCount + 1);
  EXPECT_EQ(flat.depth, bvh.depth());
  const auto ends = tsah::subtreeEnds(flat);
  ASSERT_EQ(ends.size(), flat.interiorCount);
  EXPECT_EQ(ends[0], flat.interiorCount);
  for (uint32_t i = 0; i < flat.interiorCount; ++i) {
    const auto& n = flat.frameNodes(0)[i];
    for (int c = 0; c < 2; ++c) {
      const int32_t ref = n.childRef(c);
      if (tsah::isLeafRef(ref)) continue;
      EXPECT_GT(uint32_t(ref), i);
      EXPECT_LE(ends[uint32_t(ref)], ends[i]);
    }
    if (!tsah::isLeafRef(n.ref0)) {
      EXPECT_EQ(uint32_t(n.ref0), i + 1);  // pre-order: the left child follows its parent
    }
  }
}

TEST(BvhFile, SingleLeafTree) {
  Bvh bvh;
  bvh.nodes.push_back({});
  bvh.nodes[0].primCount = 3;
  bvh.primIds = {2, 0, 1};
  tsah::PrimitiveBoxes boxes;
  boxes.frameCount = 1;
  boxes.primCount = 3;
  for (int i = 0; i < 3; ++i) {
    Aabb b;
    b.extend(tsah::Vec3{float(i), 0, 0});
    boxes.boxes.push_back(b);
  }
  tsah::refit(bvh, boxes);
  const auto bytes = tsah::encodeBvhFile(bvh, sampleInfo(3));
  const auto file = tsah::decodeBvhFile(bytes, "leaf.tbvh");
  expectSameTree(bvh, file.bvh);
}

TEST(BvhFile, SaveAndLoadThroughAFile) {
  std::mt19937 rng(3);
  const Bvh bvh = randomTree(64, 3, 8, rng);
  const auto path = (tsah::test::scratchDir() / "tree.tbvh").string();
  tsah::saveBvhFile(path, bvh, sampleInfo(64));
  const auto file = tsah::loadBvhFile(path);
  expectSameTree(bvh, file.bvh);
  EXPECT_THROW(tsah::loadBvhFile(path + ".missing"), tsah::FileError);
}

TEST(BvhFile, EncoderRejectsBadInput) {
  std::mt19937 rng(5);
  const Bvh bvh = randomTree(10, 1, 8, rng);
  auto info = sampleInfo(10);
  info.method = "a-name-that-is-far-too-long";
  EXPECT_THROW(tsah::encodeBvhFile(bvh, info), tsah::ConfigError);
  info = sampleInfo(11);
  EXPECT_THROW(tsah::encodeBvhFile(bvh, info), tsah::DataError);  // count disagrees with the tree
  EXPECT_THROW(tsah::encodeBvhFile(Bvh{}, sampleInfo(0)), tsah::DataError);
  Bvh broken = bvh;
  broken.nodes[broken.root].parent = 0;
  EXPECT_THROW(tsah::encodeBvhFile(broken, sampleInfo(10)), tsah::DataError);
}

TEST(BvhFile, TopologyHashIsCrcOfIndices) {
  const std::vector<uint32_t> indices{0, 1, 2, 2, 1, 3};
  EXPECT_EQ(tsah::topologyHash(indices), tsah::crc32(indices.data(), indices.size() * 4));
  std::vector<uint32_t> other = indices;
  std::swap(other[0], other[1]);
  EXPECT_NE(tsah::topologyHash(indices), tsah::topologyHash(other));
}

// --- corrupt input -------------------------------------------------------------------------

void fixCrc(std::vector<uint8_t>& bytes) {
  if (bytes.size() < 4) return;
  const uint32_t crc = tsah::crc32(bytes.data(), bytes.size() - 4);
  std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
}

template <typename T>
void put(std::vector<uint8_t>& bytes, std::size_t offset, T value) {
  std::memcpy(bytes.data() + offset, &value, sizeof(T));
}

TEST(BvhFile, RejectsTargetedCorruption) {
  std::mt19937 rng(9);
  const Bvh bvh = randomTree(40, 2, 4, rng);
  const auto good = tsah::encodeBvhFile(bvh, sampleInfo(40));
  auto expectError = [&](std::vector<uint8_t> bytes, const char* fragment, bool repairCrc = true) {
    if (repairCrc) fixCrc(bytes);
    try {
      tsah::decodeBvhFile(bytes, "bad.tbvh");
      ADD_FAILURE() << "accepted a file that should fail with '" << fragment << "'";
    } catch (const tsah::FileError& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  {
    auto b = good;
    b[0] = 'X';
    expectError(b, "bad magic");
  }
  {
    auto b = good;
    put<uint32_t>(b, 8, 2);
    expectError(b, "version 2");
  }
  {
    auto b = good;
    b[100] ^= 1;
    expectError(b, "checksum", false);
  }
  expectError(std::vector<uint8_t>(good.begin(), good.begin() + 100), "truncated", false);
  expectError(std::vector<uint8_t>(good.begin(), good.end() - 1), "does not match the counts", false);
  {
    auto b = good;
    put<uint32_t>(b, 24, 0xffffffffu);  // hostile triangle count
    expectError(b, "too large");
  }
  {
    auto b = good;
    put<uint32_t>(b, 40, 0x7fffffffu);  // hostile frame count: must not allocate
    expectError(b, "does not match the counts");
  }
  {
    auto b = good;
    put<uint32_t>(b, 32, 0x10000000u);  // hostile interior node count
    expectError(b, "does not match the counts");
  }
  const tsah::FlatBvh flat = tsah::flattenBvh(bvh);
  const std::size_t nodes = tsah::kTbvhHeaderBytes;
  const std::size_t triIndex = nodes + flat.nodes.size() * 64 + flat.rootBoxes.size() * sizeof(Aabb);
  {
    auto b = good;
    for (uint32_t f = 0; f < flat.frameCount; ++f)  // node 0 points to itself: a cycle
      put<int32_t>(b, nodes + (std::size_t(f) * flat.interiorCount) * 64 + 48, 0);
    expectError(b, "pre-order");
  }
  {
    auto b = good;
    put<uint32_t>(b, triIndex, 40);  // triangle id out of range
    expectError(b, "out of range");
  }
  {
    auto b = good;
    uint32_t second;
    std::memcpy(&second, b.data() + triIndex + 4, 4);
    put<uint32_t>(b, triIndex, second);  // a triangle referenced twice
    expectError(b, "more than once");
  }
  {
    auto b = good;
    put<float>(b, nodes, std::numeric_limits<float>::quiet_NaN());
    expectError(b, "not finite");
  }
  {
    auto b = good;
    put<float>(b, nodes, 1e30f);  // child box lo.x above hi.x: empty
    expectError(b, "empty");
  }
  {
    auto b = good;
    put<uint32_t>(b, 84, 1000);  // wrong depth
    expectError(b, "depth");
  }
  {
    auto b = good;
    b[112 + 15] = 'x';  // method without terminating NUL
    expectError(b, "NUL");
  }
}

// Thousands of random mutations of valid files: bit flips, byte runs, truncations, extensions and
// hostile counts, with the checksum repaired half of the time so the structural checks are reached.
TEST(BvhFile, RandomMutationsNeverCrash) {
  std::mt19937 rng(2024);
  std::vector<std::vector<uint8_t>> seeds;
  for (uint32_t prims : {1u, 5u, 60u}) seeds.push_back(tsah::encodeBvhFile(randomTree(prims, 2, 4, rng), sampleInfo(prims)));
  std::size_t accepted = 0;
  const int cases = 6000;
  for (int c = 0; c < cases; ++c) {
    auto bytes = seeds[c % seeds.size()];
    const int mutations = 1 + static_cast<int>(rng() % 4);
    for (int m = 0; m < mutations; ++m) {
      switch (rng() % 6) {
        case 0:  // flip one bit
          bytes[rng() % bytes.size()] ^= uint8_t(1u << (rng() % 8));
          break;
        case 1: {  // overwrite a run of bytes
          const std::size_t at = rng() % bytes.size();
          for (std::size_t i = at; i < std::min(bytes.size(), at + 1 + rng() % 16); ++i) bytes[i] = uint8_t(rng());
          break;
        }
        case 2:  // truncate
          bytes.resize(rng() % bytes.size());
          break;
        case 3:  // extend
          bytes.resize(bytes.size() + 1 + rng() % 64, uint8_t(rng()));
          break;
        case 4: {  // hostile count in the header
          if (bytes.size() < 56) break;
          const std::size_t field = 24 + 4 * (rng() % 8);
          const uint32_t values[] = {0u, 1u, 0x7fffffffu, 0x80000000u, 0xffffffffu, uint32_t(rng())};
          put<uint32_t>(bytes, field, values[rng() % 6]);
          break;
        }
        default: {  // a 32-bit word inside the body set to a nearby or extreme value
          if (bytes.size() < 8) break;
          const std::size_t at = (rng() % (bytes.size() / 4)) * 4;
          uint32_t v;
          std::memcpy(&v, bytes.data() + at, 4);
          const uint32_t values[] = {v + 1, v - 1, 0u, 0xffffffffu, v ^ 0x80000000u};
          put<uint32_t>(bytes, at, values[rng() % 5]);
        }
      }
      if (bytes.empty()) break;
    }
    if (rng() % 2) fixCrc(bytes);
    try {
      const tsah::BvhFile file = tsah::decodeBvhFile(bytes, "mutant.tbvh");
      ++accepted;
      const auto problem = tsah::validate(file.bvh);
      ASSERT_FALSE(problem) << "case " << c << ": " << *problem;
    } catch (const tsah::FileError& e) {
      ASSERT_NE(std::string(e.what()).find("mutant.tbvh"), std::string::npos);
    }
  }
  // Some mutations (e.g. of the build seed, with the checksum repaired) leave a valid file.
  EXPECT_GT(accepted, 0u);
  EXPECT_LT(accepted, std::size_t(cases));
}

}  // namespace
