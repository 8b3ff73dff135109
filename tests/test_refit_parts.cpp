// tsah::splitForBlockRefit: the parts cover every interior node once, subtree parts hold at most
// maxLeaves leaves, and the GPU block refit's walk (simulated here in sequence: per part, items
// arrive and the second arrival at a node carries on upwards, the top last over the subtrees' root
// boxes) gives every node's child boxes and the root box of a plain recursive refit.
#include <gtest/gtest.h>

#include <array>
#include <optional>

#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/refit_parts.hpp"

namespace {

using tsah::Aabb;

Aabb slotsBox(const tsah::FlatBvh& tree, const anim::Animation& a, uint32_t first, uint32_t count) {
  Aabb box;
  const auto p = a.keyframe(0);
  for (uint32_t s = first; s < first + count; ++s)
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = a.indices()[3 * std::size_t(tree.triIndex[s]) + c];
      box.extend(tsah::Vec3{p[3 * v], p[3 * v + 1], p[3 * v + 2]});
    }
  return box;
}

// The plain refit: the box of child `side` of node i.
Aabb childBox(const tsah::FlatBvh& tree, const anim::Animation& a, uint32_t i, int side) {
  const int32_t ref = tree.nodes[i].childRef(side);
  if (tsah::isLeafRef(ref)) return slotsBox(tree, a, tsah::leafFirstSlot(ref), tree.nodes[i].childCount(side));
  Aabb box = childBox(tree, a, uint32_t(ref), 0);
  box.extend(childBox(tree, a, uint32_t(ref), 1));
  return box;
}

bool sameBox(const Aabb& x, const Aabb& y) {
  return x.lo.x == y.lo.x && x.lo.y == y.lo.y && x.lo.z == y.lo.z && x.hi.x == y.hi.x && x.hi.y == y.hi.y &&
         x.hi.z == y.hi.z;
}

// Runs the block refit's walk over every part in launch order; returns the root box and fills
// boxes[node][side].
Aabb simulate(const tsah::FlatBvh& tree, const anim::Animation& a, const tsah::RefitParts& parts,
              std::vector<std::array<std::optional<Aabb>, 2>>& boxes) {
  boxes.assign(tree.interiorCount, {});
  std::vector<Aabb> exits(parts.parts.size());
  for (uint32_t p = 0; p < parts.parts.size(); ++p) {
    const tsah::RefitPart& part = parts.parts[p];
    std::vector<int> arrivals(part.nodeCount, 0);
    std::vector<std::array<Aabb, 2>> local(part.nodeCount);
    uint32_t exitsSeen = 0;
    for (uint32_t i = 0; i < part.itemCount; ++i) {
      const tsah::RefitPartItem& item = parts.items[part.firstItem + i];
      Aabb box;
      if (item.count == tsah::kPartEntry) {
        EXPECT_TRUE(parts.hasTop && p == parts.subtreeCount()) << "an entry outside the top";
        EXPECT_LT(item.first, parts.subtreeCount());
        box = exits[item.first];
      } else {
        box = slotsBox(tree, a, item.first, item.count);
      }
      uint32_t slot = item.parentSlot;
      bool reachedExit = true;
      while (slot != tsah::kPartExitSlot) {
        const uint32_t node = slot >> 1;
        const int side = int(slot & 1);
        EXPECT_LT(node, part.nodeCount);
        local[node][side] = box;
        boxes[parts.globalNode[part.firstNode + node]][side] = box;
        if (arrivals[node]++ == 0) {
          reachedExit = false;
          break;
        }
        box.extend(local[node][1 - side]);
        slot = parts.parentSlot[part.firstNode + node];
      }
      if (reachedExit) {
        exits[p] = box;
        ++exitsSeen;
      }
    }
    EXPECT_EQ(exitsSeen, 1u) << "part " << p;
    for (uint32_t n = 0; n < part.nodeCount; ++n) EXPECT_EQ(arrivals[n], 2) << "part " << p << " node " << n;
  }
  return exits.back();
}

void expectSplitRefitsLikeTheTree(const anim::Animation& a, uint32_t maxLeaves) {
  SCOPED_TRACE("maxLeaves " + std::to_string(maxLeaves));
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  const tsah::RefitParts parts = tsah::splitForBlockRefit(tree, maxLeaves);
  ASSERT_FALSE(parts.parts.empty());
  // Every interior node is a local node of exactly one part.
  std::vector<int> seen(tree.interiorCount, 0);
  for (const uint32_t n : parts.globalNode) ++seen[n];
  for (uint32_t n = 0; n < tree.interiorCount; ++n) ASSERT_EQ(seen[n], 1) << "node " << n;
  uint32_t leafItems = 0;
  for (uint32_t p = 0; p < parts.subtreeCount(); ++p) {
    const tsah::RefitPart& part = parts.parts[p];
    EXPECT_LE(part.itemCount, maxLeaves);
    leafItems += part.itemCount;
    // The items' slots are exactly the part's slot range, each once.
    std::vector<int> covered(part.slotCount, 0);
    for (uint32_t i = 0; i < part.itemCount; ++i) {
      const tsah::RefitPartItem& item = parts.items[part.firstItem + i];
      ASSERT_NE(item.count, tsah::kPartEntry);
      ASSERT_GE(item.first, part.firstSlot);
      ASSERT_LE(item.first + item.count, part.firstSlot + part.slotCount);
      for (uint32_t s = item.first; s < item.first + item.count; ++s) ++covered[s - part.firstSlot];
    }
    for (uint32_t s = 0; s < part.slotCount; ++s) EXPECT_EQ(covered[s], 1) << "part " << p << " slot " << s;
  }
  if (parts.hasTop) EXPECT_EQ(parts.parts.back().slotCount, 0u);
  if (parts.hasTop) {
    const tsah::RefitPart& top = parts.parts.back();
    uint32_t entries = 0;
    for (uint32_t i = 0; i < top.itemCount; ++i) entries += parts.items[top.firstItem + i].count == tsah::kPartEntry;
    EXPECT_EQ(entries, parts.subtreeCount());
    leafItems += top.itemCount - entries;
  } else {
    EXPECT_EQ(parts.parts.size(), 1u);
  }
  EXPECT_EQ(leafItems, tree.leafCount);
  std::vector<std::array<std::optional<Aabb>, 2>> boxes;
  const Aabb root = simulate(tree, a, parts, boxes);
  Aabb expectedRoot;
  for (uint32_t i = 0; i < tree.interiorCount; ++i)
    for (int side = 0; side < 2; ++side) {
      ASSERT_TRUE(boxes[i][side].has_value()) << "node " << i << " side " << side;
      EXPECT_TRUE(sameBox(*boxes[i][side], childBox(tree, a, i, side))) << "node " << i << " side " << side;
    }
  if (tree.interiorCount) {
    expectedRoot = childBox(tree, a, 0, 0);
    expectedRoot.extend(childBox(tree, a, 0, 1));
  } else {
    expectedRoot = slotsBox(tree, a, 0, tree.rootCount);
  }
  EXPECT_TRUE(sameBox(root, expectedRoot));
}

TEST(RefitParts, EverySplitRefitsLikeTheWholeTree) {
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 700, 2, 5);
  for (const uint32_t maxLeaves : {2u, 3u, 16u, 100u, 699u, 700u, 100000u}) expectSplitRefitsLikeTheTree(a, maxLeaves);
}

TEST(RefitParts, ATreeThatIsOneLeafIsOnePart) {
  const anim::Animation a({0, 1, 2}, 3, {0, 0, 0, 1, 0, 0, 0, 1, 0}, {0.0}, "triangle");
  expectSplitRefitsLikeTheTree(a, 2);
}

TEST(RefitParts, PartsOfFewerThanTwoLeavesAreRefused) {
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 50, 2, 5);
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  EXPECT_THROW(tsah::splitForBlockRefit(tree, 0), tsah::ConfigError);
  EXPECT_THROW(tsah::splitForBlockRefit(tree, 1), tsah::ConfigError);
}

}  // namespace
