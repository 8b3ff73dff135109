// The compressed 8-wide layout (cwbvh_layout.hpp, cwbvh_build.hpp): conservative quantization of
// random, degenerate, huge and tiny boxes; every node of random and real trees across frames
// contains its exact child boxes after the re-quantizing refit; the reference traversal of the
// compressed layout returns the binary CPU traversal's hits (the GPU kernels run the same code).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <limits>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/load.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/render/sampling.hpp"
#include "tsah/layout/traversal.hpp"
#include "test_support.hpp"

namespace {

using tsah::test::generatedAnimation;

using tsah::Aabb;
using tsah::CwbvhNode;
using tsah::Vec3;

// A node with `count` occupied slots (leaves) quantized over `boxes`; checks containment.
void expectConservative(const std::vector<Aabb>& boxes) {
  CwbvhNode n{};
  for (uint32_t s = 0; s < boxes.size(); ++s) n.meta[s] = uint8_t(tsah::kCwbvhLeaf | s);
  n.triCount = uint8_t(boxes.size());
  const Aabb all = tsah::cwbvhQuantize(n, boxes.data());
  for (uint32_t s = 0; s < boxes.size(); ++s) {
    const Aabb q = tsah::cwbvhChildBox(n, s);
    ASSERT_TRUE(q.contains(boxes[s])) << "slot " << s << " lo " << boxes[s].lo.x << " " << boxes[s].lo.y << " "
                                      << boxes[s].lo.z << " hi " << boxes[s].hi.x << " " << boxes[s].hi.y << " "
                                      << boxes[s].hi.z << " q.lo.x " << q.lo.x << " q.hi.x " << q.hi.x;
    ASSERT_TRUE(tsah::cwbvhChildBoxContains(n, s, boxes[s])) << "slot " << s << ": a real plane inside the box";
    ASSERT_TRUE(all.contains(boxes[s]));
  }
}

Aabb randomBox(std::mt19937& rng, float centreScale, float sizeScale) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), s(0.0f, 1.0f);
  Aabb b;
  for (int a = 0; a < 3; ++a) {
    const float c = u(rng) * centreScale;
    const float h = s(rng) * sizeScale;
    b.lo[a] = c - h;
    b.hi[a] = c + h;
  }
  return b;
}

TEST(CwbvhQuantize, ContainsRandomDegenerateHugeAndTinyBoxes) {
  std::mt19937 rng(7);
  const float scales[][2] = {{1, 1},       {1000, 1},  {1e6f, 1e-3f}, {1e-30f, 1e-32f}, {1e30f, 1e35f},
                             {1e37f, 1e38f}, {0, 1e-38f}, {5e4f, 0},     {1, 1e-7f}};
  for (auto& sc : scales) {
    for (int round = 0; round < 200; ++round) {
      const uint32_t count = 1 + rng() % 8;
      std::vector<Aabb> boxes(count);
      for (Aabb& b : boxes) b = randomBox(rng, sc[0], sc[1] * float(rng() % 3));  // some flat / point boxes
      expectConservative(boxes);
    }
  }
  // The extremes of float: the whole range, one point, boxes far from their node's origin.
  expectConservative({Aabb{{-3.4e38f, -3.4e38f, -3.4e38f}, {3.4e38f, 3.4e38f, 3.4e38f}}, Aabb{{0, 0, 0}, {0, 0, 0}}});
  expectConservative({Aabb{{1, 2, 3}, {1, 2, 3}}});
  expectConservative({Aabb{{-1e-38f, 0, 0}, {1e-38f, 1e-45f, 0}}, Aabb{{1e7f, 1e7f, 1e7f}, {1.0000001e7f, 1e7f, 1e7f}}});
}

// The quantizer settles each plane from its guess with the two neighbouring tests and searches only
// when the guess may be further off: every exponent and plane must equal the plain searches from
// the estimate and the guess (the quantizer before this shortcut), over random and extreme
// coordinates, NaN and infinities. Where the tests are monotone in q (finite planes) that is also
// the unique answer; where they are not (a plane of inf - inf), only the search's start defines it.
TEST(CwbvhQuantize, SteppedPlanesEqualTheSearch) {
  using namespace tsah::detail;
  auto referenceExponent = [](float p, float hi) {
    const float d = (hi - p) * (1.0f / 255.0f);
    uint32_t e = (tsah::floatBits(d) >> 23) & 0xffu;
    if (!(d > 0.0f)) e = 1;
    e = std::clamp<uint32_t>(e, 1, 254);
    while (e < 254 && !(tsah::rounding::addDown(p, 255.0f * tsah::cwbvhStep(e)) >= hi)) ++e;
    return e;
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const float specials[] = {0.0f, -0.0f, 1e-45f, -1e-45f, 1e-38f, 3.4e38f, -3.4e38f, inf, -inf, nan, 1.0f, -1.0f};
  uint32_t checked = 0;
  for (int round = 0; round < 200000; ++round) {
    float v[3];
    for (float& x : v) {
      if (rng() % 16 == 0) {
        x = specials[rng() % std::size(specials)];
      } else {
        const float mag = std::ldexp(u(rng), int(rng() % 200) - 100);
        x = (rng() % 2 ? mag : -mag) + (rng() % 4 == 0 ? std::ldexp(u(rng), int(rng() % 40)) : 0.0f);
      }
    }
    for (int k : {0, 1, 0})  // p <= x <= hi, NaN anywhere
      if (v[k + 1] < v[k]) std::swap(v[k], v[k + 1]);
    const float p = v[0], x = v[1], hi = v[2];
    const uint32_t e = cwbvhExponent(p, hi);
    ASSERT_EQ(e, referenceExponent(p, hi)) << p << " " << hi;
    const float step = tsah::cwbvhStep(e);
    ASSERT_EQ(cwbvhQuantizeLo(x, p, e), cwbvhSearchLo(x, p, step, cwbvhGuess(x, p, e))) << p << " " << x << " e " << e;
    ASSERT_EQ(cwbvhQuantizeHi(x, p, e), cwbvhSearchHi(x, p, step, cwbvhGuess(x, p, e))) << p << " " << x << " e " << e;
    ASSERT_EQ(cwbvhQuantizeLo(hi, p, e), cwbvhSearchLo(hi, p, step, cwbvhGuess(hi, p, e))) << p << " " << hi << " e " << e;
    ASSERT_EQ(cwbvhQuantizeHi(hi, p, e), cwbvhSearchHi(hi, p, step, cwbvhGuess(hi, p, e))) << p << " " << hi << " e " << e;
    // Finite planes: the unique answer, whatever the search starts from.
    if (e < 254 && std::isfinite(p) && std::isfinite(x) && x - p <= 3.4e38f) {
      ASSERT_EQ(cwbvhQuantizeLo(x, p, e), cwbvhSearchLo(x, p, step, 0)) << p << " " << x << " e " << e;
      ASSERT_EQ(cwbvhQuantizeHi(x, p, e), cwbvhSearchHi(x, p, step, 255)) << p << " " << x << " e " << e;
      ++checked;
    }
  }
  EXPECT_GT(checked, 150000u);
}

TEST(CwbvhQuantize, GridIsTightForOrdinaryBoxes) {
  // Quantization must not be conservative by giving up: a child a quarter of its node is at most
  // a quarter plus two grid steps.
  std::vector<Aabb> boxes = {Aabb{{0, 0, 0}, {1, 1, 1}}, Aabb{{3, 3, 3}, {4, 4, 4}}};
  CwbvhNode n{};
  n.meta[0] = tsah::kCwbvhLeaf;
  n.meta[1] = tsah::kCwbvhLeaf | 1;
  tsah::cwbvhQuantize(n, boxes.data());
  const Aabb q = tsah::cwbvhChildBox(n, 0);
  EXPECT_LE(q.hi.x, 1.0f + 2.0f * 4.0f / 255.0f);
  EXPECT_EQ(q.lo.x, 0.0f);
}

tsah::Bvh sahTreeOverFrames(std::span<const uint32_t> indices, std::span<const float> positions, uint32_t frames) {
  const tsah::PrimitiveBoxes boxes = tsah::triangleBoxes(indices, positions, frames);
  tsah::SweepSahBuilder::Config c;
  c.maxLeafSize = 8;
  tsah::Bvh bvh = tsah::SweepSahBuilder(c).build(boxes.frame(0));
  tsah::refit(bvh, boxes);
  return bvh;
}

// Structure and conservative boxes of the tree refitted to every frame.
void checkAcrossFrames(tsah::CwbvhTree& t, std::span<const uint32_t> idx, std::span<const float> positions,
                       uint32_t vertices, uint32_t frames) {
  ASSERT_EQ(tsah::validateCwbvh(t), std::nullopt);
  for (uint32_t f = 0; f < frames; ++f) {
    const auto pos = positions.subspan(std::size_t(f) * vertices * 3, std::size_t(vertices) * 3);
    tsah::refitCwbvh(t, idx, pos);
    ASSERT_EQ(tsah::validateCwbvh(t), std::nullopt) << "frame " << f;
    Aabb all;
    for (uint32_t tri = 0; tri < idx.size() / 3; ++tri)
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = idx[3 * tri + k];
        all.extend(Vec3{pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]});
      }
    ASSERT_TRUE(t.rootBox.contains(all) && all.contains(t.rootBox)) << "frame " << f;
  }
}

TEST(CwbvhBuild, RandomTreesAcrossFramesStayConservative) {
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    const auto m = tsah::test::randomMovingTriangles(300 * seed, 6, seed, 0.5f);
    const tsah::Bvh bvh = sahTreeOverFrames(m.indices, m.positions, m.frames);
    tsah::WideCollapser::Config c;
    c.width = 8;
    const tsah::WideBvh wide = tsah::WideCollapser(c).collapse(bvh);
    tsah::CwbvhTree t = tsah::buildCwbvh(wide, 0);
    ASSERT_EQ(t.triIndex.size(), m.indices.size() / 3);
    ASSERT_EQ(t.nodeCount(), wide.nodeCount());
    checkAcrossFrames(t, m.indices, m.positions, uint32_t(m.indices.size()), m.frames);
  }
}

// cwbvhLevels: every node in exactly one group, in ascending order within it; a node with only leaf
// children in group 0, any other one group above its highest interior child (so a refit group by
// group reads finished children only).
void checkLevels(const tsah::CwbvhTree& t) {
  const tsah::CwbvhLevels levels = tsah::cwbvhLevels(t);
  ASSERT_FALSE(levels.starts.empty());
  ASSERT_EQ(levels.starts.front(), 0u);
  ASSERT_EQ(levels.starts.back(), t.nodeCount());
  ASSERT_EQ(levels.nodes.size(), t.nodeCount());
  std::vector<uint32_t> groupOf(t.nodeCount(), ~0u);
  for (uint32_t h = 0; h + 1 < levels.starts.size(); ++h) {
    ASSERT_LT(levels.starts[h], levels.starts[h + 1]) << "empty group " << h;
    for (uint32_t i = levels.starts[h]; i < levels.starts[h + 1]; ++i) {
      ASSERT_LT(levels.nodes[i], t.nodeCount());
      ASSERT_EQ(groupOf[levels.nodes[i]], ~0u) << "node " << levels.nodes[i] << " twice";
      groupOf[levels.nodes[i]] = h;
      if (i > levels.starts[h]) {
        EXPECT_LT(levels.nodes[i - 1], levels.nodes[i]);
      }
    }
  }
  for (uint32_t i = 0; i < t.nodeCount(); ++i) {
    const tsah::CwbvhNode& n = t.nodes[i];
    uint32_t expected = 0, rank = 0;
    for (uint32_t s = 0; s < tsah::kCwbvhWidth; ++s)
      if (n.isInterior(s)) expected = std::max(expected, groupOf[n.childBase + rank++] + 1);
    EXPECT_EQ(groupOf[i], expected) << "node " << i;
  }
}

TEST(CwbvhBuild, LevelsGroupNodesByHeight) {
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    const auto m = tsah::test::randomMovingTriangles(500 * seed, 2, seed, 0.5f);
    tsah::CwbvhTree t = tsah::buildCwbvh(tsah::flattenBvh(sahTreeOverFrames(m.indices, m.positions, m.frames)));
    ASSERT_GT(t.depth, 1u);
    checkLevels(t);
  }
  // A one-leaf binary tree: a root with one leaf child, alone in group 0.
  const auto one = tsah::test::randomMovingTriangles(3, 1, 9, 0.5f);
  const tsah::CwbvhTree root = tsah::buildCwbvh(tsah::flattenBvh(sahTreeOverFrames(one.indices, one.positions, 1)));
  ASSERT_EQ(root.nodeCount(), 1u);
  checkLevels(root);
  EXPECT_EQ(tsah::cwbvhLevels(root).starts, (std::vector<uint32_t>{0u, 1u}));
  // A tree without nodes (the root a leaf reference) has no groups.
  EXPECT_EQ(tsah::cwbvhLevels(tsah::CwbvhTree{}).starts, std::vector<uint32_t>{0u});
}

TEST(CwbvhBuild, RealAnimationAcrossFrames) {
  const auto path = tsah::test::dataDir() / "md2" / "faerie.md2";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no " << path;
  const anim::Animation a = anim::load(path.string());
  const uint32_t frames = std::min<uint32_t>(a.keyframeCount(), 20);
  const auto all = a.allPositions();
  const std::span<const float> pos(all.data(), std::size_t(frames) * a.vertexCount() * 3);
  const tsah::Bvh bvh = sahTreeOverFrames(a.indices(), pos, frames);
  tsah::CwbvhTree t = tsah::buildCwbvh(tsah::flattenBvh(bvh));
  checkAcrossFrames(t, a.indices(), pos, a.vertexCount(), frames);
}

// buildCwbvh(flat, objective) passes the collapse constants on (the GPU runtime's
// Config::wideObjective): over a tree of one-triangle leaves, cheap triangles merge leaves up to the
// limit, and a limit of 1 keeps every leaf single.
TEST(CwbvhBuild, CollapseConstantsAndLeafLimitReachTheCollapse) {
  const auto m = tsah::test::randomMovingTriangles(400, 2, 5, 0.1f);
  const tsah::PrimitiveBoxes boxes = m.boxes();
  tsah::SweepSahBuilder::Config c;
  c.maxLeafSize = 1;
  tsah::Bvh bvh = tsah::SweepSahBuilder(c).build(boxes.frame(0));
  tsah::refit(bvh, boxes);
  const tsah::FlatBvh flat = tsah::flattenBvh(bvh);
  auto largestLeaf = [](const tsah::CwbvhTree& t) {
    uint32_t largest = 0;
    for (const tsah::CwbvhLeaf& l : t.leaves) largest = std::max(largest, l.count);
    return largest;
  };
  const tsah::CwbvhTree merged = tsah::buildCwbvh(flat, tsah::Objective{0, {3.0f, 0.1f}, 4});
  const tsah::CwbvhTree single = tsah::buildCwbvh(flat, tsah::Objective{0, {3.0f, 0.1f}, 1});
  ASSERT_EQ(tsah::validateCwbvh(merged), std::nullopt);
  ASSERT_EQ(tsah::validateCwbvh(single), std::nullopt);
  EXPECT_GT(largestLeaf(merged), 1u);
  EXPECT_LE(largestLeaf(merged), 4u);
  EXPECT_EQ(largestLeaf(single), 1u);
  EXPECT_LT(merged.leaves.size(), single.leaves.size());
}

// buildCwbvh(flat, objective) is the CPU wide layouts' collapse (WideCollapser(wideCollapseConfig(
// objective, 8))), and on the input of the objective tests (wideObjectiveCase, which the GPU's
// CudaCwbvh.CollapseFollowsTheObjective uses too) each part of the objective changes the tree: a
// collapse that dropped k, the cost constants or the leaf limit would make another one. A limit
// above 8 collapses as 8 (a compressed node holds at most 64 triangles).
TEST(CwbvhBuild, EveryPartOfTheObjectiveShapesTheTree) {
  using tsah::test::hostCwbvh;
  using tsah::test::sameCwbvh;
  const tsah::test::WideObjectiveCase c = tsah::test::wideObjectiveCase();
  const tsah::Objective& objective = c.objective;
  const tsah::CwbvhTree tree = hostCwbvh(c.tree, objective);
  ASSERT_EQ(tsah::validateCwbvh(tree), std::nullopt);
  EXPECT_TRUE(sameCwbvh(tsah::buildCwbvh(c.tree, objective), tree));
  uint32_t largest = 0;
  for (const tsah::CwbvhLeaf& l : tree.leaves) largest = std::max(largest, l.count);
  EXPECT_GT(largest, 1u);
  EXPECT_LE(largest, objective.maxLeafSize);

  EXPECT_FALSE(sameCwbvh(tsah::buildCwbvh(c.tree), tree)) << "the default objective";
  EXPECT_FALSE(sameCwbvh(tsah::buildCwbvh(c.tree, tsah::Objective{}), tree)) << "the default objective";
  tsah::Objective other = objective;
  other.k = 0;
  EXPECT_FALSE(sameCwbvh(hostCwbvh(c.tree, other), tree)) << "k = 0";
  other = objective;
  other.cost = tsah::CostModel{};
  EXPECT_FALSE(sameCwbvh(hostCwbvh(c.tree, other), tree)) << "cT = 3, cI = 2";
  other = objective;
  other.maxLeafSize = 8;
  EXPECT_FALSE(sameCwbvh(hostCwbvh(c.tree, other), tree)) << "leaves of up to 8";

  tsah::Objective large = objective;
  large.maxLeafSize = 16;
  EXPECT_TRUE(sameCwbvh(tsah::buildCwbvh(c.tree, large), hostCwbvh(c.tree, other)));
}

TEST(CwbvhBuild, RefusesTooWideTreesAndOverfullNodes) {
  const auto m = tsah::test::randomMovingTriangles(100, 1, 3, 0.0f);
  const tsah::Bvh bvh = sahTreeOverFrames(m.indices, m.positions, 1);
  tsah::WideCollapser::Config c;
  c.width = 8;
  tsah::WideBvh wide = tsah::WideCollapser(c).collapse(bvh);
  wide.width = 9;
  EXPECT_THROW(tsah::buildCwbvh(wide), tsah::Error);
  // Two leaf children of 50 triangles each: 100 triangles in one node.
  tsah::WideBvh two;
  two.rootRef = 0;
  two.nodes = {{0, 2}};
  two.children = {{tsah::makeLeafRef(0), 50}, {tsah::makeLeafRef(50), 50}};
  two.primIds.resize(100);
  for (uint32_t i = 0; i < 100; ++i) two.primIds[i] = i;
  two.childBoxes = {Aabb{{0, 0, 0}, {1, 1, 1}}, Aabb{{1, 1, 1}, {2, 2, 2}}};
  two.rootBoxes = {Aabb{{0, 0, 0}, {2, 2, 2}}};
  EXPECT_THROW(tsah::buildCwbvh(two), tsah::Error);
}

void compareWithBinary(const anim::Animation& a, uint32_t rayCount, uint32_t seed) {
  const tsah::Bvh bvh = sahTreeOverFrames(a.indices(), a.allPositions(), a.keyframeCount());
  const tsah::FlatBvh flat = tsah::flattenBvh(bvh);
  tsah::CwbvhTree t = tsah::buildCwbvh(flat);
  tsah::CpuRuntime rt(flat, {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  auto refitted = [&](std::span<const float> pos, const tsah::BvhView&) -> const tsah::CwbvhTree& {
    tsah::refitCwbvh(t, a.indices(), pos);
    return t;
  };
  tsah::test::expectWideTraversalMatchesBinary(a, rt, rayCount, seed, refitted);
}

TEST(CwbvhTraversal, EqualsBinaryTraversal) {
  compareWithBinary(generatedAnimation(anim::GeneratorKind::Explode, 3000, 8), 3000, 1);
  compareWithBinary(generatedAnimation(anim::GeneratorKind::Wave, 3000, 8), 3000, 2);
  compareWithBinary(generatedAnimation(anim::GeneratorKind::Swap, 3000, 8), 3000, 3);
}

TEST(CwbvhTraversal, SingleLeafTree) {
  const auto m = tsah::test::randomMovingTriangles(5, 2, 9, 0.1f);
  const tsah::PrimitiveBoxes boxes = m.boxes();
  tsah::Bvh bvh;
  bvh.frameCount = 2;
  bvh.nodes.resize(1);
  bvh.nodes[0].primCount = 5;
  bvh.primIds = {4, 2, 0, 1, 3};
  bvh.boxes.resize(2);
  tsah::refit(bvh, boxes);
  tsah::CwbvhTree t = tsah::buildCwbvh(tsah::flattenBvh(bvh));
  ASSERT_TRUE(tsah::isLeafRef(t.rootRef));
  ASSERT_EQ(tsah::validateCwbvh(t), std::nullopt);
  const std::span<const float> pos(m.positions.data(), 5 * 9);
  tsah::refitCwbvh(t, m.indices, pos);
  const auto woop = tsah::test::cwbvhWoop(t, m.indices, pos);
  const tsah::CwbvhView v = t.view(woop.data(), m.indices.data(), pos.data());
  for (uint32_t tri = 0; tri < 5; ++tri) {  // a ray through each triangle's centre hits something
    Vec3 c{0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      const uint32_t i = m.indices[3 * tri + k];
      c = c + Vec3{pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]} * (1.0f / 3.0f);
    }
    const tsah::Ray ray{c + Vec3{0, 0, 10}, 0.0f, Vec3{0, 0, -1}, 1e30f};
    EXPECT_TRUE(tsah::cwbvhClosestHit(v, ray).valid());
    EXPECT_TRUE(tsah::cwbvhAnyHit(v, ray));
  }
}

}  // namespace

namespace {

// The traversal's slot masks (interiorSlots, leafSlots from the meta words) and the octant
// permutation agree with the per-slot definitions for every meta pattern kind and octant.
// The box test takes each slot's entry / exit through a three-way max / min of the slab distances'
// bits (cwbvhSlabEntry / cwbvhSlabExit). Against the float form: never a shorter interval (entry at
// or below, exit at or above), so every box the float form enters is entered; the float max / min
// where the three distances are non-negative, the float min / max where all are negative. Over
// random, signed-zero, infinite and NaN distances, and ray intervals whose bounds are not NaN.
TEST(CwbvhTraversal, SlabBitsWidenTheFloatInterval) {
  using tsah::rounding::maxNum;
  using tsah::rounding::minNum;
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const float specials[] = {0.0f, -0.0f, inf, -inf, nan, -nan, 1e-45f, -1e-45f, 3.4e38f, -3.4e38f};
  auto pick = [&]() {
    if (rng() % 6 == 0) return specials[rng() % std::size(specials)];
    return u(rng) * std::ldexp(1.0f, int(rng() % 60) - 30);
  };
  uint32_t entered = 0, sameSign = 0;
  for (int round = 0; round < 300000; ++round) {
    const float a = pick(), b = pick(), c = pick(), d = pick(), e = pick(), f = pick();
    const float tmin = rng() % 4 == 0 ? 0.0f : std::fabs(u(rng)) * 1e-3f;
    float tmax = rng() % 4 == 0 ? inf : std::fabs(pick());
    if (std::isnan(tmax)) tmax = 1.0f;  // a NaN bound: the triangle test never reports a hit anyway
    const float entryFloat = maxNum(maxNum(a, b), maxNum(c, tmin));
    const float exitFloat = minNum(minNum(d, e), minNum(f, tmax));
    const float entryBits = tsah::cwbvhSlabEntry(a, b, c, tmin), exitBits = tsah::cwbvhSlabExit(d, e, f, tmax);
    ASSERT_FALSE(entryBits > entryFloat) << a << " " << b << " " << c << " " << tmin;
    ASSERT_FALSE(exitBits < exitFloat) << d << " " << e << " " << f << " " << tmax;
    if (entryFloat <= exitFloat) {
      ASSERT_TRUE(entryBits <= exitBits) << a << " " << b << " " << c << " | " << d << " " << e << " " << f << " " << tmax;
      ++entered;
    }
    // Bits of non-negative floats order like the floats, of negative ones the other way round.
    const bool noNan = !std::isnan(a) && !std::isnan(b) && !std::isnan(c);
    const auto below = [](float x, float y) { return x < y || (x == y && std::signbit(x) && !std::signbit(y)); };
    if (noNan && !std::signbit(a) && !std::signbit(b) && !std::signbit(c)) {
      ASSERT_EQ(tsah::cwbvhBitsMax3(a, b, c), std::max({a, b, c}, below));
      ASSERT_EQ(tsah::cwbvhBitsMin3(a, b, c), std::min({a, b, c}, below));
      ++sameSign;
    } else if (noNan && std::signbit(a) && std::signbit(b) && std::signbit(c)) {
      ASSERT_EQ(tsah::cwbvhBitsMax3(a, b, c), std::min({a, b, c}, below));
      ASSERT_EQ(tsah::cwbvhBitsMin3(a, b, c), std::max({a, b, c}, below));
      ++sameSign;
    }
  }
  EXPECT_GT(entered, 3000u);  // 5,808 with this seed
  EXPECT_GT(sameSign, 50000u);
}

TEST(CwbvhTraversal, SlotMasksAndOctantPermutation) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 2000; ++trial) {
    CwbvhNode n{};
    for (uint32_t s = 0; s < 8; ++s) {
      const uint32_t kind = uint32_t(rng() % 3);
      n.meta[s] = kind == 0 ? 0 : kind == 1 ? tsah::kCwbvhInterior : uint8_t(tsah::kCwbvhLeaf | uint32_t(rng() % 64));
    }
    tsah::CwbvhNodeWords w;
    std::memcpy(w.w, &n, sizeof w.w);
    uint32_t interior = 0, leaves = 0;
    for (uint32_t s = 0; s < 8; ++s) {
      interior |= n.isInterior(s) ? 1u << s : 0u;
      leaves |= n.isLeaf(s) ? 1u << s : 0u;
    }
    ASSERT_EQ(w.interiorSlots(), interior);
    ASSERT_EQ(w.leafSlots(), leaves);
    for (uint32_t s = 0; s < 8; ++s) ASSERT_EQ(w.metaOf(s), n.meta[s]);
    const uint32_t mask = uint32_t(rng() & 0xffu);
    for (uint32_t oct = 0; oct < 8; ++oct) {
      uint32_t expected = 0;
      for (uint32_t s = 0; s < 8; ++s) expected |= ((mask >> s) & 1u) << (s ^ oct);
      ASSERT_EQ(tsah::cwbvhPermuteSlots(mask, oct), expected);
    }
  }
}

}  // namespace
