#pragma once
// Clusters of a binary tree for the clustered refit walk (refit_walk.cuh's refitClustersUpwards):
// the tree cut into pieces of three levels, each at most 7 interior nodes under one cluster root.
// The global walk pays a round trip to L2 (an arrival counter and the sibling's box) at every
// level of the tree; the clustered walk pays it once per cluster, so a tree of depth D costs about
// D / 3 round trips: the last child to arrive at a cluster computes its nodes' boxes in registers.
#include <cstdint>
#include <vector>

#include "device_types.hpp"

namespace tsah::cuda::detail {

struct RefitClusterSet {
  std::vector<RefitCluster> clusters;
  std::vector<RefitClusterNode> nodes;  // the clusters' interior nodes, children before parents
  std::vector<uint32_t> leafCluster;    // per leaf record: the cluster of its parent node
};

// From the refit topology: parent[n] = the parent slot (2 * parent + side) of interior node n, or
// kNoParent at the root; leaves as the refit walk reads them. Clusters start at the depths 0, 3,
// 6, ... below the root. An empty result for a tree that is one leaf (its walk has no node).
RefitClusterSet buildRefitClusters(const std::vector<uint32_t>& parent, const std::vector<LeafRecord>& leaves);

}  // namespace tsah::cuda::detail
