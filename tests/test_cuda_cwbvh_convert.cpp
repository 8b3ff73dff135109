// The device's conversion of a binary tree into the compressed 8-wide layout (GpuCwbvhConverter,
// cuda_kernels/src/cwbvh_rebuild.hpp: a node per group of 8 lanes), driven directly with trees the
// GPU rebuilders never make: random SAH trees with leaves of 1, 4 and 8 triangles and every merge
// limit, tiny trees and invalid ones. Valid trees give tsah::convertToCwbvh's bytes; invalid ones
// are refused with tsah::Error (no hang, no out-of-range write: the GPU sanitizers run this
// program), and the converter works again afterwards. Skipped without a device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"
#include "cwbvh_rebuild.hpp"
#include "tsah/layout/cwbvh_convert.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"

namespace {

namespace tc = tsah::cuda;

tsah::FlatBvh sahTree(const tsah::test::MovingTriangles& m, uint32_t maxLeaf) {
  tsah::SweepSahBuilder::Config c;
  c.maxLeafSize = maxLeaf;
  return tsah::flattenBvh(tsah::SweepSahBuilder(c).build(m.boxes().frame(0)));
}

// The device's conversion of frame 0 of `flat` (its node block, triIndex and root uploaded as the
// rebuilders leave them), downloaded; throws what collect() throws.
tsah::CwbvhTree deviceConversion(tc::detail::GpuCwbvhConverter& converter, const tsah::FlatBvh& flat, uint32_t merge) {
  tc::detail::RootInfo root;
  root.box = flat.rootBoxes[0];
  root.ref = flat.rootRef;
  root.count = flat.rootCount;
  root.interiorCount = flat.interiorCount;
  const tc::DeviceBuffer<tsah::GpuBvhNode> nodes(flat.frameNodes(0));
  const tc::DeviceBuffer<uint32_t> triIndex(std::span<const uint32_t>(flat.triIndex));
  const tc::DeviceBuffer<tc::detail::RootInfo> rootBuffer(std::span<const tc::detail::RootInfo>(&root, 1));
  converter.enqueue(nodes.data(), flat.interiorCount, triIndex.data(), rootBuffer.data(), merge, nullptr);
  converter.collect(nullptr);
  return converter.download(nullptr);
}

void expectHostBytes(tc::detail::GpuCwbvhConverter& converter, const tsah::FlatBvh& flat, uint32_t merge) {
  const tsah::CwbvhTree host = tsah::convertToCwbvh(flat, 0, merge);
  const tsah::CwbvhTree device = deviceConversion(converter, flat, merge);
  ASSERT_EQ(device.nodes.size(), host.nodes.size());
  EXPECT_EQ(std::memcmp(device.nodes.data(), host.nodes.data(), host.nodes.size() * sizeof(tsah::CwbvhNode)), 0);
  EXPECT_EQ(device.triIndex, host.triIndex);
  EXPECT_EQ(converter.levels(), host.depth);
}

TEST(CudaCwbvhConvert, RandomTreesEqualHostEmulation) {
  REQUIRE_GPU();
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    const auto m = tsah::test::randomMovingTriangles(700 * seed, 1, seed, 0.0f);
    tc::detail::GpuCwbvhConverter converter(uint32_t(m.indices.size() / 3));
    for (uint32_t maxLeaf : {1u, 4u, 8u}) {
      const tsah::FlatBvh flat = sahTree(m, maxLeaf);
      for (uint32_t merge : {0u, 3u, 8u}) {
        SCOPED_TRACE("seed " + std::to_string(seed) + " max leaf " + std::to_string(maxLeaf) + " merge " +
                     std::to_string(merge));
        expectHostBytes(converter, flat, merge);
      }
    }
  }
}

// One leaf of one or five triangles (the root is a leaf: one block, no interior node) and two
// leaves under a root.
TEST(CudaCwbvhConvert, TinyTrees) {
  REQUIRE_GPU();
  const auto one = tsah::test::randomMovingTriangles(1, 1, 5, 0.0f);
  const auto five = tsah::test::randomMovingTriangles(5, 1, 6, 0.0f);
  for (const auto& [m, sizes] : {std::pair{one, std::vector<uint32_t>{1}}, std::pair{five, std::vector<uint32_t>{5}},
                                 std::pair{five, std::vector<uint32_t>{2, 3}}}) {
    tc::detail::GpuCwbvhConverter converter(uint32_t(m.indices.size() / 3));
    expectHostBytes(converter, tsah::test::tinyTree(m, sizes), 0);
  }
}

// The invalid trees the host emulation refuses (ConvertToCwbvh.RefusesInvalidTrees): every one is
// refused on the device too, and the same converter then converts a valid tree correctly.
TEST(CudaCwbvhConvert, RefusesInvalidTrees) {
  REQUIRE_GPU();
  const auto m = tsah::test::randomMovingTriangles(100, 1, 3, 0.0f);
  const tsah::FlatBvh good = sahTree(m, 8);
  tc::detail::GpuCwbvhConverter converter(100);
  std::vector<std::pair<std::string, tsah::FlatBvh>> bad;
  bad.emplace_back("100 triangles under one wide node", tsah::test::tinyTree(m, {50, 50}));
  {
    tsah::FlatBvh t = good;
    t.nodes[0].ref1 = int32_t(t.interiorCount);
    t.nodes[0].count1 = 0;
    bad.emplace_back("a reference past the nodes", t);
  }
  {
    tsah::FlatBvh t = good;
    const int side = tsah::isLeafRef(t.nodes[0].ref0) ? 1 : 0;
    const uint32_t child = uint32_t(t.nodes[0].childRef(side));
    (side == 0 ? t.nodes[child].ref0 : t.nodes[child].ref1) = 0;
    (side == 0 ? t.nodes[child].count0 : t.nodes[child].count1) = 0;
    bad.emplace_back("a cycle", t);
  }
  {
    tsah::FlatBvh t = good;
    for (tsah::GpuBvhNode& n : t.nodes)
      if (tsah::isLeafRef(n.ref0)) {
        n.ref0 = tsah::makeLeafRef(t.triangleCount() - 1);
        n.count0 = 2;
        break;
      }
    bad.emplace_back("a leaf past the triangles", t);
  }
  for (const auto& [what, tree] : bad) {
    SCOPED_TRACE(what);
    EXPECT_THROW(tsah::convertToCwbvh(tree, 0, 0), tsah::Error);
    EXPECT_THROW(deviceConversion(converter, tree, 0), tsah::Error);
  }
  expectHostBytes(converter, good, 0);
  EXPECT_THROW(deviceConversion(converter, good, tsah::kCwbvhMaxLeafTriangles + 1), tsah::Error);
}

}  // namespace

#else
TEST(CudaCwbvhConvert, NotBuilt) { GTEST_SKIP() << "built without CUDA"; }
#endif
