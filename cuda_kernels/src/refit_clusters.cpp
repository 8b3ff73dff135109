// The clusters of the clustered refit walk (refit_clusters.hpp).
#include "refit_clusters.hpp"

#include <algorithm>

#include "tsah/base/error.hpp"

namespace tsah::cuda::detail {

RefitClusterSet buildRefitClusters(const std::vector<uint32_t>& parent, const std::vector<LeafRecord>& leaves) {
  RefitClusterSet set;
  const auto interior = uint32_t(parent.size());
  if (interior == 0) return set;
  // Depth of every interior node: parents are followed until a node of known depth.
  std::vector<uint32_t> depth(interior, kNoParent), chain;
  for (uint32_t n = 0; n < interior; ++n) {
    uint32_t m = n;
    while (depth[m] == kNoParent && parent[m] != kNoParent) {
      chain.push_back(m);
      m = parent[m] >> 1;
      if (chain.size() > interior) throw Failure("refit clusters: the tree's parents form a cycle");
    }
    uint32_t d = depth[m] == kNoParent ? (depth[m] = 0) : depth[m];
    while (!chain.empty()) {
      depth[chain.back()] = ++d;
      chain.pop_back();
    }
  }
  // Nodes by depth: a node's cluster is known once its parent's is.
  std::vector<uint32_t> order(interior);
  for (uint32_t n = 0; n < interior; ++n) order[n] = n;
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return depth[a] < depth[b]; });
  std::vector<uint32_t> clusterOf(interior), localIndex(interior);
  std::vector<std::vector<uint32_t>> members;
  for (uint32_t n : order) {
    if (depth[n] % 3 == 0) {
      clusterOf[n] = uint32_t(members.size());
      members.emplace_back();
    } else {
      clusterOf[n] = clusterOf[parent[n] >> 1];
    }
  }
  // Children before parents inside a cluster: the deepest first.
  for (auto it = order.rbegin(); it != order.rend(); ++it) {
    localIndex[*it] = uint32_t(members[clusterOf[*it]].size());
    members[clusterOf[*it]].push_back(*it);
  }
  set.clusters.resize(members.size());
  for (uint32_t c = 0; c < members.size(); ++c) {
    RefitCluster& cluster = set.clusters[c];
    cluster.firstNode = uint32_t(set.nodes.size());
    cluster.nodeCount = uint32_t(members[c].size());
    const uint32_t root = members[c].back();
    cluster.parentSlot = parent[root];
    cluster.parentCluster = parent[root] == kNoParent ? kNoParent : clusterOf[parent[root] >> 1];
    for (uint32_t n : members[c]) set.nodes.push_back({n, {kExternalChild, kExternalChild}});
  }
  // A child inside its parent's cluster is read from the cluster's registers; any other child (a
  // leaf, another cluster's root) arrives from outside and is counted.
  for (uint32_t n = 0; n < interior; ++n) {
    if (parent[n] == kNoParent) continue;
    const uint32_t p = parent[n] >> 1;
    if (clusterOf[n] == clusterOf[p]) {
      set.nodes[set.clusters[clusterOf[p]].firstNode + localIndex[p]].local[parent[n] & 1] = uint8_t(localIndex[n]);
    } else {
      ++set.clusters[clusterOf[p]].arrivals;
    }
  }
  set.leafCluster.reserve(leaves.size());
  for (const LeafRecord& leaf : leaves) {
    const uint32_t c = clusterOf[leaf.parentSlot >> 1];
    ++set.clusters[c].arrivals;
    set.leafCluster.push_back(c);
  }
  return set;
}

}  // namespace tsah::cuda::detail
