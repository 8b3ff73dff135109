// tsah::findMovingParts against brute force: a slot moves when any vertex of its triangle does, an
// interior node when any slot below it does; every node and slot of a tree over a scene with a
// static part, over a scene where everything moves and where nothing does.
#include <gtest/gtest.h>

#include <functional>

#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/moving_parts.hpp"

namespace {

// The slots below interior node i, by walking the tree.
void slotsBelow(const tsah::FlatBvh& tree, uint32_t i, const std::function<void(uint32_t)>& visit) {
  const tsah::GpuBvhNode& n = tree.nodes[i];
  for (int c = 0; c < 2; ++c) {
    const int32_t ref = n.childRef(c);
    if (tsah::isLeafRef(ref)) {
      for (uint32_t s = tsah::leafFirstSlot(ref); s < tsah::leafFirstSlot(ref) + n.childCount(c); ++s) visit(s);
    } else {
      slotsBelow(tree, uint32_t(ref), visit);
    }
  }
}

void expectBruteForce(const anim::Animation& a, std::span<const uint32_t> moving) {
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  const tsah::MovingParts parts = tsah::findMovingParts(tree, a.indices(), moving, a.vertexCount());
  std::vector<bool> vertexMoves(a.vertexCount(), false);
  for (uint32_t v : moving) vertexMoves[v] = true;
  uint32_t movingSlots = 0;
  for (uint32_t s = 0; s < tree.triangleCount(); ++s) {
    const uint32_t* tri = a.indices().data() + 3 * std::size_t(tree.triIndex[s]);
    const bool moves = vertexMoves[tri[0]] || vertexMoves[tri[1]] || vertexMoves[tri[2]];
    ASSERT_EQ(parts.slotMoves[s] != 0, moves) << "slot " << s;
    movingSlots += moves;
  }
  EXPECT_EQ(parts.movingSlots, movingSlots);
  uint32_t movingNodes = 0;
  for (uint32_t i = 0; i < tree.interiorCount; ++i) {
    bool moves = false;
    slotsBelow(tree, i, [&](uint32_t s) { moves = moves || parts.slotMoves[s] != 0; });
    ASSERT_EQ(parts.nodeMoves[i] != 0, moves) << "node " << i;
    movingNodes += moves;
  }
  EXPECT_EQ(parts.movingNodes, movingNodes);
}

TEST(MovingParts, EqualBruteForceOnAMostlyStaticScene) {
  const anim::Animation a = tsah::test::mostlyStaticAnimation(3000, 500);
  ASSERT_FALSE(a.allMoving());
  expectBruteForce(a, a.movingVertices());
}

TEST(MovingParts, EverythingAndNothing) {
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 800, 3);
  std::vector<uint32_t> all(a.vertexCount());
  for (uint32_t v = 0; v < a.vertexCount(); ++v) all[v] = v;
  expectBruteForce(a, all);
  expectBruteForce(a, {});
  // One moving vertex.
  const std::vector<uint32_t> one{a.vertexCount() / 2};
  expectBruteForce(a, one);
}

TEST(MovingParts, RefusesIdsOutOfRangeAndAnotherTopology) {
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 200, 2);
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  const std::vector<uint32_t> bad{a.vertexCount()};
  EXPECT_THROW(tsah::findMovingParts(tree, a.indices(), bad, a.vertexCount()), tsah::DataError);
  EXPECT_THROW(tsah::findMovingParts(tree, a.indices().subspan(3), {}, a.vertexCount()), tsah::DataError);
}

}  // namespace
