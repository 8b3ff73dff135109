// The tree passes that split a large tree's top levels into parallel tasks (refit, validate,
// limitDepth, the leaf collapse and its compaction, flattenBvh): on trees past the size where they
// go parallel, their results equal plain recursive references bit for bit, on every thread count,
// and validate still finds every corruption.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstring>
#include <functional>
#include <random>
#include <vector>

#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/optimize/leaf_collapser.hpp"

namespace {

using tsah::Aabb;
using tsah::Bvh;

constexpr uint32_t kPrims = 40000;  // leaf size 1: 80k nodes, past the parallel passes' threshold

tsah::PrimitiveBoxes randomBoxes(uint32_t frames, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(-50.0f, 50.0f), size(0.01f, 1.5f);
  tsah::PrimitiveBoxes prims;
  prims.frameCount = frames;
  prims.primCount = kPrims;
  prims.boxes.resize(std::size_t(frames) * kPrims);
  for (uint32_t p = 0; p < kPrims; ++p) {
    const tsah::Vec3 c{pos(rng), pos(rng), pos(rng)}, d{pos(rng) * 0.02f, pos(rng) * 0.02f, pos(rng) * 0.02f};
    const float s = size(rng);
    for (uint32_t f = 0; f < frames; ++f) {
      const tsah::Vec3 at{c.x + f * d.x, c.y + f * d.y, c.z + f * d.z};
      prims.boxes[std::size_t(f) * kPrims + p] = Aabb{{at.x - s, at.y - s, at.z - s}, {at.x + s, at.y + s, at.z + s}};
    }
  }
  return prims;
}

// A binned SAH tree over frame 0 with leaves of one primitive, refitted to every frame.
Bvh bigTree(const tsah::PrimitiveBoxes& prims) {
  tsah::BinnedSahBuilder::Config config;
  config.maxLeafSize = 1;
  Bvh bvh = tsah::BinnedSahBuilder(config).build(prims.frame(0));
  tsah::refit(bvh, prims);
  return bvh;
}

bool sameBoxes(const std::vector<Aabb>& a, const std::vector<Aabb>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Aabb)) == 0;
}

void expectSameTree(const Bvh& got, const Bvh& want) {
  ASSERT_EQ(got.nodes.size(), want.nodes.size());
  EXPECT_EQ(got.root, want.root);
  EXPECT_EQ(got.primIds, want.primIds);
  for (std::size_t n = 0; n < want.nodes.size(); ++n) {
    const tsah::BvhNode &a = got.nodes[n], &b = want.nodes[n];
    ASSERT_TRUE(a.parent == b.parent && a.left == b.left && a.right == b.right && a.primBegin == b.primBegin &&
                a.primCount == b.primCount)
        << "node " << n;
  }
  EXPECT_TRUE(sameBoxes(got.boxes, want.boxes));
}

// The compaction's numbering by recursion: a node's children take the next two indices, then the
// left subtree is numbered, then the right; flagged nodes become leaves of every primitive below.
Bvh referenceCompact(const Bvh& tree, const std::vector<uint8_t>& asLeaf) {
  Bvh out;
  out.frameCount = tree.frameCount;
  out.nodes.emplace_back();
  std::vector<uint32_t> origin{tree.root};
  std::function<void(uint32_t, uint32_t)> gather = [&](uint32_t n, uint32_t into) {
    const tsah::BvhNode& node = tree.nodes[n];
    if (node.isLeaf()) {
      for (uint32_t i = 0; i < node.primCount; ++i) out.primIds.push_back(tree.primIds[node.primBegin + i]);
      out.nodes[into].primCount += node.primCount;
      return;
    }
    gather(node.left, into);
    gather(node.right, into);
  };
  std::function<void(uint32_t, uint32_t)> expand = [&](uint32_t n, uint32_t index) {
    const tsah::BvhNode& node = tree.nodes[n];
    if (node.isLeaf() || (!asLeaf.empty() && asLeaf[n])) {
      out.nodes[index].primBegin = uint32_t(out.primIds.size());
      gather(n, index);
      return;
    }
    const auto left = uint32_t(out.nodes.size());
    out.nodes.emplace_back().parent = index;
    out.nodes.emplace_back().parent = index;
    origin.push_back(node.left);
    origin.push_back(node.right);
    out.nodes[index].left = left;
    out.nodes[index].right = left + 1;
    expand(node.left, left);
    expand(node.right, left + 1);
  };
  expand(tree.root, 0);
  for (uint32_t o : origin)
    for (uint32_t f = 0; f < tree.frameCount; ++f) out.boxes.push_back(tree.box(o, f));
  return out;
}

// The k = 0 collapse decisions by recursion (the greedy rule, exact for k = 0).
std::vector<uint8_t> referenceLeafFlags(const Bvh& tree, const tsah::Objective& objective) {
  std::vector<uint8_t> flags(tree.nodes.size(), 0);
  std::vector<double> factor(tree.frameCount);
  for (uint32_t f = 0; f < tree.frameCount; ++f)
    factor[f] = (1.0 / tree.frameCount) / tree.box(tree.root, f).area();
  std::function<std::pair<uint32_t, double>(uint32_t)> visit = [&](uint32_t n) -> std::pair<uint32_t, double> {
    const tsah::BvhNode& node = tree.nodes[n];
    double area = 0.0;
    for (uint32_t f = 0; f < tree.frameCount; ++f) area += factor[f] * tree.box(n, f).area();
    if (node.isLeaf()) return {node.primCount, objective.cost.ci * node.primCount * area};
    const auto l = visit(node.left), r = visit(node.right);
    const uint32_t count = l.first + r.first;
    const double keep = objective.cost.ct * area + l.second + r.second, leaf = objective.cost.ci * count * area;
    if (count <= objective.maxLeafSize && leaf <= keep) {
      flags[n] = 1;
      return {count, leaf};
    }
    return {count, keep};
  };
  visit(tree.root);
  return flags;
}

// The flat layout by recursion: interior nodes numbered in pre-order, leaves' slots in order.
tsah::FlatBvh referenceFlatten(const Bvh& tree) {
  tsah::FlatBvh flat;
  flat.frameCount = tree.frameCount;
  flat.leafCount = tree.leafCount();
  flat.interiorCount = tree.nodeCount() - flat.leafCount;
  flat.nodes.resize(std::size_t(flat.frameCount) * flat.interiorCount);
  for (uint32_t f = 0; f < flat.frameCount; ++f) flat.rootBoxes.push_back(tree.box(tree.root, f));
  uint32_t next = 0;
  std::function<void(uint32_t, uint32_t, int, uint32_t)> visit = [&](uint32_t n, uint32_t parent, int side,
                                                                    uint32_t depth) {
    const tsah::BvhNode& node = tree.nodes[n];
    flat.depth = std::max(flat.depth, depth);
    int32_t ref;
    uint32_t count = 0;
    if (node.isLeaf()) {
      ref = tsah::makeLeafRef(uint32_t(flat.triIndex.size()));
      count = node.primCount;
      for (uint32_t i = 0; i < node.primCount; ++i) flat.triIndex.push_back(tree.primIds[node.primBegin + i]);
    } else {
      ref = int32_t(next++);
    }
    if (parent == tsah::kInvalidIndex) {
      flat.rootRef = ref;
      flat.rootCount = count;
    } else {
      for (uint32_t f = 0; f < flat.frameCount; ++f) {
        tsah::GpuBvhNode& p = flat.frameNodes(f)[parent];
        p.setChildBox(side, tree.box(n, f));
        (side == 0 ? p.ref0 : p.ref1) = ref;
        (side == 0 ? p.count0 : p.count1) = count;
      }
    }
    if (!node.isLeaf()) {
      visit(node.left, uint32_t(ref), 0, depth + 1);
      visit(node.right, uint32_t(ref), 1, depth + 1);
    }
  };
  visit(tree.root, tsah::kInvalidIndex, 0, 0);
  return flat;
}

// Runs `body` with at most `threads` TBB threads.
template <class Body>
void withThreads(int threads, const Body& body) {
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  body();
}

TEST(ParallelTreePasses, RefitIsTheUnionOfEachNodesSubtree) {
  const tsah::PrimitiveBoxes prims = randomBoxes(3, 1);
  Bvh tree = bigTree(prims);
  ASSERT_GE(tree.nodes.size(), std::size_t(1) << 16);
  // Tight boxes: each leaf the union of its primitives', each interior node its children's.
  for (uint32_t n = 0; n < tree.nodeCount(); ++n)
    for (uint32_t f = 0; f < 3; ++f) {
      const tsah::BvhNode& node = tree.nodes[n];
      Aabb want;
      if (node.isLeaf()) {
        for (uint32_t i = 0; i < node.primCount; ++i) want.extend(prims.at(f, tree.primIds[node.primBegin + i]));
      } else {
        want = tsah::merge(tree.box(node.left, f), tree.box(node.right, f));
      }
      ASSERT_EQ(std::memcmp(&want, &tree.box(n, f), sizeof(Aabb)), 0) << "node " << n << " frame " << f;
    }
  const std::vector<Aabb> boxes = tree.boxes;
  withThreads(1, [&] { tsah::refit(tree, prims); });
  EXPECT_TRUE(sameBoxes(tree.boxes, boxes));
  EXPECT_FALSE(tsah::validate(tree, &prims).has_value());
}

TEST(ParallelTreePasses, CollapseAndCompactionEqualTheRecursion) {
  const tsah::PrimitiveBoxes prims = randomBoxes(2, 2);
  const Bvh tree = bigTree(prims);
  expectSameTree(tsah::LeafCollapser::compact(tree), referenceCompact(tree, {}));
  const tsah::Objective objective{0, {}, 4};
  const std::vector<uint8_t> flags = referenceLeafFlags(tree, objective);
  const Bvh want = referenceCompact(tree, flags);
  ASSERT_LT(want.nodes.size(), tree.nodes.size());
  Bvh collapsed = tsah::LeafCollapser(objective).collapse(tree);
  expectSameTree(collapsed, want);
  withThreads(1, [&] { collapsed = tsah::LeafCollapser(objective).collapse(tree); });
  expectSameTree(collapsed, want);
  EXPECT_FALSE(tsah::validate(collapsed, &prims).has_value());
}

TEST(ParallelTreePasses, FlattenEqualsTheRecursion) {
  const tsah::PrimitiveBoxes prims = randomBoxes(2, 3);
  const Bvh tree = bigTree(prims);
  const tsah::FlatBvh want = referenceFlatten(tree);
  for (int threads : {1, 4}) {
    tsah::FlatBvh got;
    withThreads(threads, [&] { got = tsah::flattenBvh(tree); });
    EXPECT_EQ(got.depth, want.depth);
    EXPECT_EQ(got.rootRef, want.rootRef);
    EXPECT_EQ(got.interiorCount, want.interiorCount);
    EXPECT_EQ(got.triIndex, want.triIndex);
    ASSERT_EQ(got.nodes.size(), want.nodes.size());
    EXPECT_EQ(std::memcmp(got.nodes.data(), want.nodes.data(), want.nodes.size() * sizeof(tsah::GpuBvhNode)), 0);
    EXPECT_FALSE(tsah::validateFlatBvh(got).has_value());
  }
}

TEST(ParallelTreePasses, ValidateFindsEachCorruptionOfALargeTree) {
  const tsah::PrimitiveBoxes prims = randomBoxes(1, 4);
  const Bvh tree = bigTree(prims);
  ASSERT_FALSE(tsah::validate(tree, &prims).has_value());
  // An interior node deep in the tree (below the parallel levels) and one near the root.
  std::vector<uint32_t> interior;
  for (uint32_t n = 0; n < tree.nodeCount(); ++n)
    if (!tree.nodes[n].isLeaf() && n != tree.root) interior.push_back(n);
  for (uint32_t victim : {interior.front(), interior[interior.size() / 2], interior.back()}) {
    const tsah::BvhNode node = tree.nodes[victim];
    Bvh shared = tree;  // both children the same node
    shared.nodes[victim].right = node.left;
    EXPECT_TRUE(tsah::validate(shared).has_value()) << victim;
    Bvh cycle = tree;  // a child pointing back up at the root
    cycle.nodes[victim].left = cycle.root;
    EXPECT_TRUE(tsah::validate(cycle).has_value()) << victim;
    Bvh loose = tree;  // a box that no longer holds its child
    loose.box(victim, 0).hi.x = loose.box(victim, 0).lo.x;
    EXPECT_TRUE(tsah::validate(loose).has_value()) << victim;
  }
  Bvh duplicate = tree;  // a primitive in two leaves, another in none
  for (uint32_t& p : duplicate.primIds)
    if (p == 7) p = 8;
  const auto problem = tsah::validate(duplicate);
  ASSERT_TRUE(problem.has_value());
  EXPECT_NE(problem->find("more than one leaf"), std::string::npos) << *problem;
  Bvh moved = tree;  // a primitive outside its leaf's box in the boxes given
  tsah::PrimitiveBoxes far = prims;
  far.boxes[123].hi.x += 1000.0f;
  EXPECT_TRUE(tsah::validate(moved, &far).has_value());
}

TEST(ParallelTreePasses, DepthLimitOfADeepLargeTree) {
  // A caterpillar: every interior node has a leaf on its left, 70k levels deep.
  const uint32_t leaves = 70000;
  Bvh chain;
  chain.frameCount = 1;
  for (uint32_t i = 0; i < leaves; ++i) chain.primIds.push_back(i);
  chain.nodes.resize(2 * leaves - 1);
  for (uint32_t i = 0; i + 1 < leaves; ++i) {  // interior i: left leaf leaves-1+i, right interior i+1
    const uint32_t leaf = leaves - 1 + i, right = i + 1 < leaves - 1 ? i + 1 : 2 * leaves - 2;
    chain.nodes[i].left = leaf;
    chain.nodes[i].right = right;
    chain.nodes[leaf].parent = chain.nodes[right].parent = i;
  }
  for (uint32_t i = 0; i < leaves; ++i) {
    chain.nodes[leaves - 1 + i].primBegin = i;
    chain.nodes[leaves - 1 + i].primCount = 1;
  }
  tsah::PrimitiveBoxes prims;
  prims.frameCount = 1;
  prims.primCount = leaves;
  for (uint32_t i = 0; i < leaves; ++i) prims.boxes.push_back(Aabb{{float(i), 0, 0}, {float(i) + 1, 1, 1}});
  tsah::refit(chain, prims);
  ASSERT_FALSE(tsah::validate(chain, &prims).has_value());
  EXPECT_EQ(chain.depth(), leaves - 1);
  EXPECT_TRUE(tsah::limitDepth(chain, 64));
  EXPECT_LE(chain.depth(), 64u);
  EXPECT_FALSE(tsah::validate(chain, &prims).has_value());
  EXPECT_FALSE(tsah::limitDepth(chain, 64));
}

}  // namespace
