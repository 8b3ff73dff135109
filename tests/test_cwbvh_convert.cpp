// The conversion of a binary tree (GpuBvhNode form) into the compressed 8-wide layout
// (cwbvh_convert.hpp): the host emulation of the GPU conversion of the per-frame rebuilds. The
// result is a valid compressed tree (every triangle once, decoded boxes containing the exact ones,
// the same nodes as a refit from the triangles gives), whose traversal returns the binary
// traversal's hits; tiny trees work, invalid binary trees are refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <numeric>

#include "tsah/base/error.hpp"
#include "anim/load.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah/build/sah_builder.hpp"
#include "test_support.hpp"

namespace {

using tsah::Aabb;
using tsah::Vec3;

tsah::FlatBvh sahTree(std::span<const uint32_t> indices, std::span<const float> positions, uint32_t maxLeaf) {
  tsah::SweepSahBuilder::Config c;
  c.maxLeafSize = maxLeaf;
  return tsah::flattenBvh(tsah::SweepSahBuilder(c).build(tsah::triangleBoxes(indices, positions, 1).frame(0)));
}

bool sameBytes(const std::vector<tsah::CwbvhNode>& a, const std::vector<tsah::CwbvhNode>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(tsah::CwbvhNode)) == 0;
}

// Everything a converted tree must satisfy: valid (validateCwbvh: structure, every slot in one
// leaf, every decoded box containing its exact box), triIndex a permutation, no more nodes than
// binary interior nodes, leaves of at most 8 triangles (merged ones at most mergeLimit), and the
// nodes a refit from the triangles at the same positions gives (the exact boxes are the binary
// tree's, which are the triangles' bounds).
void expectGoodConversion(const tsah::FlatBvh& flat, const tsah::CwbvhTree& t, std::span<const uint32_t> indices,
                          std::span<const float> positions) {
  ASSERT_EQ(tsah::validateCwbvh(t), std::nullopt);
  ASSERT_EQ(t.rootRef, 0);
  ASSERT_LE(t.nodeCount(), std::max(1u, flat.interiorCount));
  std::vector<uint32_t> ids = t.triIndex;
  std::sort(ids.begin(), ids.end());
  std::vector<uint32_t> expect(flat.triangleCount());
  std::iota(expect.begin(), expect.end(), 0u);
  ASSERT_EQ(ids, expect);
  for (const tsah::CwbvhLeaf& leaf : t.leaves) ASSERT_LE(leaf.count, tsah::kCwbvhMaxLeafTriangles);
  tsah::CwbvhTree refitted = t;
  tsah::refitCwbvh(refitted, indices, positions);
  EXPECT_TRUE(sameBytes(refitted.nodes, t.nodes));
  EXPECT_TRUE(refitted.rootBox.contains(t.rootBox) && t.rootBox.contains(refitted.rootBox));
}

TEST(ConvertToCwbvh, RandomTreesAreValid) {
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    const auto m = tsah::test::randomMovingTriangles(250 * seed, 1, seed, 0.0f);
    for (uint32_t maxLeaf : {1u, 4u, 8u}) {
      const tsah::FlatBvh flat = sahTree(m.indices, m.positions, maxLeaf);
      for (uint32_t merge : {0u, 3u, 8u}) {
        SCOPED_TRACE("seed " + std::to_string(seed) + " max leaf " + std::to_string(maxLeaf) + " merge " +
                     std::to_string(merge));
        const tsah::CwbvhTree t = tsah::convertToCwbvh(flat, 0, merge);
        expectGoodConversion(flat, t, m.indices, m.positions);
        // Merging turns small subtrees into one leaf: with one triangle per binary leaf, wide leaves
        // hold more than one triangle only when merging is on, and never more than the limit.
        uint32_t largest = 0;
        for (const tsah::CwbvhLeaf& leaf : t.leaves) largest = std::max(largest, leaf.count);
        if (maxLeaf == 1) {
          EXPECT_LE(largest, std::max(1u, merge));
          if (merge >= 2) {
            EXPECT_GE(largest, 2u);
          }
        }
        // The greedy opening fills nodes: a node with fewer than 8 children has only leaves.
        for (const tsah::CwbvhNode& n : t.nodes) {
          uint32_t children = 0, interior = 0;
          for (uint32_t s = 0; s < tsah::kCwbvhWidth; ++s) {
            children += n.isEmpty(s) ? 0 : 1;
            interior += n.isInterior(s) ? 1 : 0;
          }
          if (children < tsah::kCwbvhWidth) {
            EXPECT_EQ(interior, 0u);
          }
        }
      }
    }
  }
}

// The binary CPU runtime's tree at each time, converted, traced against the binary traversal.
void compareWithBinary(const anim::Animation& a, uint32_t rayCount, uint32_t seed,
                       uint32_t merge = tsah::kCwbvhDefaultMergeTriangles) {
  const tsah::FlatBvh flat = sahTree(a.indices(), a.positionsAt(a.startTime()), 8);
  tsah::CpuRuntime rt(flat, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  tsah::CwbvhTree t;
  auto convert = [&](std::span<const float> pos, const tsah::BvhView& bv) -> const tsah::CwbvhTree& {
    const tsah::BinaryTreeView binary{bv.nodes, flat.interiorCount, bv.triIndex, a.triangleCount()};
    t = tsah::convertToCwbvh(binary, bv.rootRef, bv.rootCount, bv.rootBox, merge);
    tsah::FlatBvh now = flat;  // the binary tree at these positions
    now.nodes.assign(bv.nodes, bv.nodes + flat.interiorCount);
    now.rootBoxes = {bv.rootBox};
    expectGoodConversion(now, t, a.indices(), pos);
    return t;
  };
  tsah::test::expectWideTraversalMatchesBinary(a, rt, rayCount, seed, convert);
}

TEST(ConvertToCwbvh, SameHitsAsBinaryTraversal) {
  compareWithBinary(tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 3000, 8), 3000, 1);
  compareWithBinary(tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 3000, 8), 3000, 2);
  compareWithBinary(tsah::test::generatedAnimation(anim::GeneratorKind::Swap, 3000, 8), 3000, 3);
  // Small binary subtrees merged into wide leaves.
  compareWithBinary(tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 3000, 8), 3000, 5, 3);
  compareWithBinary(tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 3000, 8), 3000, 6, 8);
}

TEST(ConvertToCwbvh, RealAnimation) {
  const auto path = tsah::test::dataDir() / "md2" / "faerie.md2";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no " << path;
  compareWithBinary(anim::load(path.string()), 3000, 4);
}

void expectEveryTriangleHit(const tsah::CwbvhTree& t, const tsah::test::MovingTriangles& m) {
  const auto woop = tsah::test::cwbvhWoop(t, m.indices, m.positions);
  const tsah::CwbvhView v = t.view(woop.data(), m.indices.data(), m.positions.data());
  for (uint32_t tri = 0; tri < m.indices.size() / 3; ++tri) {
    Vec3 c{0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      const uint32_t i = m.indices[3 * tri + k];
      c = c + Vec3{m.positions[3 * i], m.positions[3 * i + 1], m.positions[3 * i + 2]} * (1.0f / 3.0f);
    }
    const tsah::Ray ray{c + Vec3{0, 0, 10}, 0.0f, Vec3{0, 0, -1}, 1e30f};
    EXPECT_TRUE(tsah::cwbvhClosestHit(v, ray).valid()) << "triangle " << tri;
    EXPECT_TRUE(tsah::cwbvhAnyHit(v, ray)) << "triangle " << tri;
  }
}

TEST(ConvertToCwbvh, OneTriangleOneLeafAndTwoLeaves) {
  const auto one = tsah::test::randomMovingTriangles(1, 1, 5, 0.0f);
  const auto five = tsah::test::randomMovingTriangles(5, 1, 6, 0.0f);
  for (const auto& [m, sizes] : {std::pair{one, std::vector<uint32_t>{1}}, std::pair{five, std::vector<uint32_t>{5}},
                                 std::pair{five, std::vector<uint32_t>{2, 3}}}) {
    const tsah::FlatBvh flat = tsah::test::tinyTree(m, sizes);
    const tsah::CwbvhTree t = tsah::convertToCwbvh(flat);
    // Always a root node (the GPU's trace reads no leaf root): one child per binary leaf.
    ASSERT_EQ(t.nodeCount(), 1u);
    EXPECT_EQ(t.leaves.size(), sizes.size());
    expectGoodConversion(flat, t, m.indices, m.positions);
    expectEveryTriangleHit(t, m);
  }
}

TEST(ConvertToCwbvh, RefusesInvalidTrees) {
  const auto m = tsah::test::randomMovingTriangles(100, 1, 3, 0.0f);
  // Two leaves of 50 triangles: 100 under one wide node (binary leaves of <= 8 never do this).
  EXPECT_THROW(tsah::convertToCwbvh(tsah::test::tinyTree(m, {50, 50})), tsah::DataError);
  const tsah::FlatBvh good = sahTree(m.indices, m.positions, 8);
  EXPECT_NO_THROW(tsah::convertToCwbvh(good));
  EXPECT_THROW(tsah::convertToCwbvh(good, 0, tsah::kCwbvhMaxLeafTriangles + 1), tsah::ConfigError);
  EXPECT_THROW(tsah::convertToCwbvh(good, 1), tsah::ConfigError);  // no such frame
  {
    tsah::FlatBvh bad = good;  // a reference past the nodes
    bad.nodes[0].ref1 = int32_t(bad.interiorCount);
    bad.nodes[0].count1 = 0;
    EXPECT_THROW(tsah::convertToCwbvh(bad, 0, 0), tsah::DataError);
  }
  {
    tsah::FlatBvh bad = good;  // a cycle: a child refers back to the root
    const int side = tsah::isLeafRef(bad.nodes[0].ref0) ? 1 : 0;
    const uint32_t child = uint32_t(bad.nodes[0].childRef(side));
    (side == 0 ? bad.nodes[child].ref0 : bad.nodes[child].ref1) = 0;
    (side == 0 ? bad.nodes[child].count0 : bad.nodes[child].count1) = 0;
    EXPECT_THROW(tsah::convertToCwbvh(bad, 0, 0), tsah::DataError);
  }
  {
    tsah::FlatBvh bad = good;  // a leaf past the triangles
    for (tsah::GpuBvhNode& n : bad.nodes)
      if (tsah::isLeafRef(n.ref0)) {
        n.ref0 = tsah::makeLeafRef(bad.triangleCount() - 1);
        n.count0 = 2;
        break;
      }
    EXPECT_THROW(tsah::convertToCwbvh(bad, 0, 0), tsah::DataError);
  }
}

}  // namespace
