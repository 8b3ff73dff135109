// The clusters of the GPU's clustered refit walk (cuda_kernels/src/refit_clusters.hpp), checked on
// the host against the trees they cut: every interior node in exactly one cluster of at most 7,
// children before parents, each cluster's root last and linked to the cluster above, the outside
// arrivals counted, every leaf sent to its parent's cluster, and a walk of depth D cut into
// ceil((D + 1) / 3) clusters. The device walk itself is compared with the level-by-level walk in
// test_cuda_two_level (bit for bit). Needs no device.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <random>
#include <vector>

#include "refit_clusters.hpp"

namespace {

using tsah::cuda::detail::kExternalChild;
using tsah::cuda::detail::kNoParent;
using tsah::cuda::detail::LeafRecord;

// A random binary tree over `leaves` leaves (random splits: unbalanced, deep): parent slots of its
// interior nodes and its leaf records.
struct RandomTree {
  std::vector<uint32_t> parent;
  std::vector<LeafRecord> leaves;
  std::vector<uint32_t> depth;  // per interior node
};

void split(RandomTree& t, uint32_t count, uint32_t parentSlot, uint32_t depth, std::mt19937& rng) {
  if (count == 1) {
    t.leaves.push_back({parentSlot, uint32_t(t.leaves.size()), 1});
    return;
  }
  const auto node = uint32_t(t.parent.size());
  t.parent.push_back(parentSlot);
  t.depth.push_back(depth);
  const uint32_t left = std::uniform_int_distribution<uint32_t>(1, count - 1)(rng);
  split(t, left, 2 * node, depth + 1, rng);
  split(t, count - left, 2 * node + 1, depth + 1, rng);
}

RandomTree randomTree(uint32_t leaves, uint32_t seed) {
  RandomTree t;
  std::mt19937 rng(seed);
  split(t, leaves, kNoParent, 0, rng);
  return t;
}

TEST(RefitClusters, CutEveryTreeIntoClustersOfThreeLevels) {
  for (const uint32_t leaves : {2u, 3u, 8u, 9u, 100u, 5000u}) {
    for (uint32_t seed = 1; seed <= 4; ++seed) {
      const RandomTree t = randomTree(leaves, seed);
      const auto set = tsah::cuda::detail::buildRefitClusters(t.parent, t.leaves);
      const auto interior = uint32_t(t.parent.size());
      std::vector<uint32_t> clusterOf(interior, kNoParent);
      uint32_t arrivals = 0, roots = 0;
      for (uint32_t c = 0; c < set.clusters.size(); ++c) {
        const auto& cluster = set.clusters[c];
        ASSERT_GE(cluster.nodeCount, 1u);
        ASSERT_LE(cluster.nodeCount, 7u);
        arrivals += cluster.arrivals;
        for (uint32_t k = 0; k < cluster.nodeCount; ++k) {
          const auto& n = set.nodes[cluster.firstNode + k];
          ASSERT_LT(n.node, interior);
          ASSERT_EQ(clusterOf[n.node], kNoParent) << "node " << n.node << " in two clusters";
          clusterOf[n.node] = c;
          EXPECT_EQ(t.depth[n.node] / 3, t.depth[set.nodes[cluster.firstNode + cluster.nodeCount - 1].node] / 3);
          for (int side = 0; side < 2; ++side) {
            if (n.local[side] == kExternalChild) continue;
            ASSERT_LT(n.local[side], k) << "a child after its parent";
            EXPECT_EQ(t.parent[set.nodes[cluster.firstNode + n.local[side]].node], 2 * n.node + side);
          }
        }
        const uint32_t root = set.nodes[cluster.firstNode + cluster.nodeCount - 1].node;
        EXPECT_EQ(t.depth[root] % 3, 0u);
        EXPECT_EQ(cluster.parentSlot, t.parent[root]);
        roots += cluster.parentSlot == kNoParent ? 1 : 0;
      }
      EXPECT_EQ(roots, 1u);
      for (uint32_t n = 0; n < interior; ++n) ASSERT_NE(clusterOf[n], kNoParent) << "node " << n << " in no cluster";
      for (const auto& cluster : set.clusters) {
        if (cluster.parentSlot != kNoParent) EXPECT_EQ(cluster.parentCluster, clusterOf[cluster.parentSlot >> 1]);
      }
      // Each leaf arrives once, and each cluster's root once at the cluster above.
      EXPECT_EQ(arrivals, t.leaves.size() + set.clusters.size() - 1);
      ASSERT_EQ(set.leafCluster.size(), t.leaves.size());
      for (std::size_t i = 0; i < t.leaves.size(); ++i)
        EXPECT_EQ(set.leafCluster[i], clusterOf[t.leaves[i].parentSlot >> 1]);
      // A child counted as an arrival is exactly one that is not read from the cluster's registers.
      uint32_t external = 0;
      for (const auto& n : set.nodes) external += (n.local[0] == kExternalChild) + (n.local[1] == kExternalChild);
      EXPECT_EQ(external, arrivals);
    }
  }
}

TEST(RefitClusters, AOneLeafTreeHasNone) {
  const auto set = tsah::cuda::detail::buildRefitClusters({}, {{kNoParent, 0, 3}});
  EXPECT_TRUE(set.clusters.empty());
  EXPECT_TRUE(set.nodes.empty());
}

}  // namespace

#else
TEST(RefitClusters, NotBuilt) { GTEST_SKIP() << "built without CUDA"; }
#endif
