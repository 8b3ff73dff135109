// The bound on tree depth (kMaxBvhDepth, limitDepth in tsah/core/bvh.hpp): every tree the library
// makes fits the runtimes' traversal stacks, and a deeper tree read from a file is refused naming
// the file. The inputs that used to give deeper trees: identical triangles (the sequential
// optimizer chained them, depth 161 for 2,000) and nested triangles of growing size (the parallel
// optimizer, depth 158 for 180).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/layout/wide_layout.hpp"
#include "tsah/pipeline.hpp"

namespace {

using tsah::Aabb;
using tsah::Bvh;
using tsah::kMaxBvhDepth;

Aabb box(tsah::Vec3 lo, tsah::Vec3 hi) {
  Aabb b;
  b.lo = lo;
  b.hi = hi;
  return b;
}

bool same(const Aabb& a, const Aabb& b) {
  return a.lo.x == b.lo.x && a.lo.y == b.lo.y && a.lo.z == b.lo.z && a.hi.x == b.hi.x && a.hi.y == b.hi.y &&
         a.hi.z == b.hi.z;
}

// A chain: each interior node has one leaf and the rest of the chain as children (depth leaves - 1).
// Leaf i holds primitive i, boxed [i, i+1] in x, shifted by the frame in y.
Bvh chainTree(uint32_t leaves, uint32_t frames) {
  Bvh bvh;
  bvh.frameCount = frames;
  for (uint32_t i = 0; i < leaves; ++i) bvh.primIds.push_back(i);
  // Interior nodes 0 .. leaves-2 (node i at depth i), leaves after them.
  const uint32_t interior = leaves - 1;
  bvh.nodes.resize(interior + leaves);
  for (uint32_t i = 0; i < interior; ++i) {
    tsah::BvhNode& n = bvh.nodes[i];
    n.parent = i == 0 ? tsah::kInvalidIndex : i - 1;
    n.left = interior + i;
    n.right = i + 1 < interior ? i + 1 : interior + i + 1;
    bvh.nodes[n.left].parent = i;
    bvh.nodes[n.right].parent = i;
  }
  for (uint32_t l = 0; l < leaves; ++l) {
    bvh.nodes[interior + l].primBegin = l;
    bvh.nodes[interior + l].primCount = 1;
  }
  bvh.boxes.resize(bvh.nodes.size() * frames);
  for (uint32_t l = 0; l < leaves; ++l)
    for (uint32_t f = 0; f < frames; ++f)
      bvh.box(interior + l, f) = box({float(l), float(f), 0.0f}, {float(l) + 1.0f, float(f) + 1.0f, 1.0f});
  for (uint32_t i = interior; i-- > 0;)
    for (uint32_t f = 0; f < frames; ++f)
      bvh.box(i, f) = tsah::merge(bvh.box(bvh.nodes[i].left, f), bvh.box(bvh.nodes[i].right, f));
  return bvh;
}

tsah::PrimitiveBoxes leafBoxes(const Bvh& bvh) {
  tsah::PrimitiveBoxes prims;
  prims.frameCount = bvh.frameCount;
  prims.primCount = bvh.primCount();
  prims.boxes.resize(std::size_t(prims.frameCount) * prims.primCount);
  for (uint32_t n = 0; n < bvh.nodeCount(); ++n)
    if (bvh.nodes[n].isLeaf())
      for (uint32_t f = 0; f < bvh.frameCount; ++f)
        prims.boxes[std::size_t(f) * prims.primCount + bvh.primIds[bvh.nodes[n].primBegin]] = bvh.box(n, f);
  return prims;
}

TEST(DepthLimit, AChainIsRebuiltBalancedBelowTheBoundKeepingLeavesAndBoxes) {
  Bvh bvh = chainTree(300, 2);
  ASSERT_EQ(bvh.depth(), 299u);
  const tsah::PrimitiveBoxes prims = leafBoxes(bvh);
  const Bvh before = bvh;
  EXPECT_TRUE(tsah::limitDepth(bvh));
  EXPECT_LE(bvh.depth(), kMaxBvhDepth);
  EXPECT_EQ(tsah::validate(bvh, &prims), std::nullopt);
  EXPECT_EQ(bvh.nodeCount(), before.nodeCount());
  EXPECT_EQ(bvh.root, before.root);
  EXPECT_EQ(bvh.primIds, before.primIds);
  for (uint32_t n = 0; n < bvh.nodeCount(); ++n) {
    if (!bvh.nodes[n].isLeaf()) continue;
    EXPECT_EQ(bvh.nodes[n].primBegin, before.nodes[n].primBegin);
    for (uint32_t f = 0; f < 2; ++f) EXPECT_TRUE(same(bvh.box(n, f), before.box(n, f)));
  }
  for (uint32_t f = 0; f < 2; ++f) EXPECT_TRUE(same(bvh.box(bvh.root, f), before.box(before.root, f)));
  // The top of the chain stays: only the lowest subtrees that had to change did.
  for (uint32_t i = 0; i < 100; ++i) EXPECT_EQ(bvh.nodes[i].left, before.nodes[i].left) << i;
  EXPECT_FALSE(tsah::limitDepth(bvh));  // already within the bound
}

TEST(DepthLimit, AnyBoundThatCanHoldTheLeavesIsMet) {
  for (uint32_t bound : {7u, 8u, 10u, 40u}) {
    Bvh bvh = chainTree(100, 1);
    const tsah::PrimitiveBoxes prims = leafBoxes(bvh);
    EXPECT_TRUE(tsah::limitDepth(bvh, bound));
    EXPECT_LE(bvh.depth(), bound);
    EXPECT_EQ(tsah::validate(bvh, &prims), std::nullopt);
  }
  Bvh bvh = chainTree(100, 1);
  EXPECT_THROW(tsah::limitDepth(bvh, 6), tsah::ConfigError);  // 100 leaves need 7 levels
}

TEST(DepthLimit, AShallowTreeIsLeftAlone) {
  Bvh bvh = chainTree(129, 1);  // depth 128: exactly the bound
  const Bvh before = bvh;
  EXPECT_FALSE(tsah::limitDepth(bvh));
  EXPECT_EQ(bvh.nodes.size(), before.nodes.size());
  for (uint32_t n = 0; n < bvh.nodeCount(); ++n) EXPECT_EQ(bvh.nodes[n].left, before.nodes[n].left);
}

TEST(DepthLimit, TheRuntimesStacksHoldTheBound) {
  EXPECT_LE(kMaxBvhDepth, tsah::kTraversalStackSize);
  EXPECT_LE(tsah::wideStackNeed<8>(kMaxBvhDepth), tsah::kWideStackSize);  // a wide tree is no deeper
}

// `count` triangles, one keyframe, each (0,0,0) (size,0,0) (0,1,0) with size(i).
template <class Size>
anim::Animation triangles(uint32_t count, Size size) {
  std::vector<uint32_t> indices;
  std::vector<float> positions;
  for (uint32_t i = 0; i < count; ++i) {
    const float s = size(i);
    positions.insert(positions.end(), {0, 0, 0, s, 0, 0, 0, 1, 0});
    indices.insert(indices.end(), {3 * i, 3 * i + 1, 3 * i + 2});
  }
  return anim::Animation(std::move(indices), 3 * count, std::move(positions), {0.0}, "fixture");
}

// Every method and optimizer gives a tree within the bound that is valid and traces on the CPU in
// every layout.
void expectBoundedAndTraceable(const anim::Animation& a) {
  for (const char* method : {"sah0", "sahstar", "tsah0", "tsah2"})
    for (tsah::OptimizerKind optimizer : {tsah::OptimizerKind::Sequential, tsah::OptimizerKind::Parallel})
      for (uint32_t maxLeaf : {1u, 8u}) {
        SCOPED_TRACE(std::string(method) + " " + tsah::name(optimizer) + " max leaf " + std::to_string(maxLeaf));
        tsah::TreeOptions options;
        const tsah::MethodSpec spec = tsah::MethodSpec::parse(method);
        options.method = spec.method;
        options.objective = {spec.k, {}, maxLeaf};
        options.optimizer = optimizer;
        options.threads = 2;
        const tsah::OptimizedTree tree = tsah::optimizeAnimation(a, options);
        EXPECT_LE(tree.bvh.depth(), kMaxBvhDepth);
        const tsah::PrimitiveBoxes prims = tsah::representativeBoxes(a, 1);
        EXPECT_EQ(tsah::validate(tree.bvh, &prims), std::nullopt);
        const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
        for (tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
          tsah::CpuRuntime::Config config(1);
          config.layout = layout;
          tsah::CpuRuntime runtime(tsah::flattenBvh(tree.bvh), indices, a.vertexCount(), config);
          runtime.update(a.positionsAt(0.0));
          const tsah::Ray ray{{0.1f, 0.1f, -1.0f}, 0.0f, {0.0f, 0.0f, 1.0f}, 10.0f};
          const tsah::Hit hit = runtime.closestHit(ray);
          EXPECT_TRUE(hit.valid()) << tsah::name(layout);
          EXPECT_NEAR(hit.t, 1.0f, 1e-5f) << tsah::name(layout);
          EXPECT_TRUE(runtime.anyHit(ray)) << tsah::name(layout);
        }
      }
}

TEST(DepthLimit, IdenticalTrianglesGiveBoundedTreesWithEveryMethod) {
  expectBoundedAndTraceable(triangles(2000, [](uint32_t) { return 1.0f; }));
}

TEST(DepthLimit, NestedTrianglesOfGrowingSizeGiveBoundedTreesWithEveryMethod) {
  expectBoundedAndTraceable(triangles(180, [](uint32_t i) { return float(std::pow(1.25, double(i))); }));
}

TEST(DepthLimit, TheSahBuildersStayWithinTheBound) {
  std::vector<Aabb> boxes;
  for (uint32_t i = 0; i < 180; ++i) boxes.push_back(box({0, 0, 0}, {float(std::pow(1.25, double(i))), 1, 0}));
  EXPECT_LE(tsah::SweepSahBuilder(tsah::SweepSahBuilder::Config{}).build(boxes).depth(), kMaxBvhDepth);
  EXPECT_LE(tsah::BinnedSahBuilder(tsah::BinnedSahBuilder::Config{}).build(boxes).depth(), kMaxBvhDepth);
}

TEST(DepthLimit, ATooDeepTreeFileIsRefusedNamingTheFile) {
  const std::filesystem::path path = tsah::test::scratchDir() / "deep.tbvh";
  const Bvh deep = chainTree(200, 1);
  tsah::saveBvhFile(path.string(), deep, {});
  const std::string expected = path.string() + ": tree depth 199 exceeds the limit of 128 levels";
  try {
    tsah::loadBvhFile(path.string());
    ADD_FAILURE() << "a tree of depth 199 was read";
  } catch (const tsah::FileError& e) {
    EXPECT_EQ(std::string(e.what()), expected);
  }
  try {  // the path of `tsah trace` and `tsah export`
    tsah::loadTreeSetFile(path.string());
    ADD_FAILURE() << "a tree of depth 199 was read as a set";
  } catch (const tsah::FileError& e) {
    EXPECT_EQ(std::string(e.what()), expected);
  }
  tsah::saveBvhFile(path.string(), chainTree(129, 1), {});  // depth 128: read
  EXPECT_EQ(tsah::loadBvhFile(path.string()).bvh.depth(), kMaxBvhDepth);
}

}  // namespace
