// The host side shared by every reinsertion backend (reinsertion_rounds.hpp): the optimizer's node
// numbering, the levels of the first refit, the topology back as a Bvh, the input checks.
#include <algorithm>
#include <string>
#include <utility>

#include "tsah/optimize/detail/reinsertion_rounds.hpp"

#include "tsah/base/error.hpp"

namespace tsah::reinsertion {

NumberedTree numberTree(const Bvh& tree) {
  if (tree.nodes.empty()) throw tsah::DataError("ParallelReinsertionOptimizer: empty tree");
  NumberedTree out;
  const std::vector<uint32_t> order = childrenFirstOrder(tree);
  std::vector<uint32_t> id(tree.nodes.size(), kNone);
  uint32_t inner = 0, leaves = 0;
  for (uint32_t n : order) (tree.nodes[n].isLeaf() ? leaves : inner)++;
  out.innerCount = inner;
  out.nodeCount = inner + leaves;
  uint32_t nextInner = 0, nextLeaf = inner;
  for (uint32_t n : order) id[n] = tree.nodes[n].isLeaf() ? nextLeaf++ : nextInner++;
  out.links.assign(out.nodeCount, Links{kNone, kNone, kNone});
  for (uint32_t n : order) {
    const BvhNode& node = tree.nodes[n];
    Links& l = out.links[id[n]];
    l.parent = node.parent == kNone ? kNone : id[node.parent];
    if (node.isLeaf()) {
      l.left = node.primBegin;
      l.right = node.primCount;
      out.primTotal += node.primCount;
    } else {
      l.left = id[node.left];
      l.right = id[node.right];
    }
  }
  out.root = id[tree.root];
  return out;
}

std::vector<uint32_t> refitLevels(const NumberedTree& tree, std::vector<uint32_t>& order) {
  // Interior nodes are numbered children first: one ascending pass sees children before parents.
  std::vector<uint32_t> height(tree.innerCount, 1);
  uint32_t highest = 0;
  const auto heightOf = [&](uint32_t n) { return n < tree.innerCount ? height[n] : 0u; };
  for (uint32_t n = 0; n < tree.innerCount; ++n) {
    height[n] = 1 + std::max(heightOf(tree.links[n].left), heightOf(tree.links[n].right));
    highest = std::max(highest, height[n]);
  }
  std::vector<uint32_t> offsets(highest + 1, 0);  // counting sort by height
  for (uint32_t n = 0; n < tree.innerCount; ++n) ++offsets[height[n]];
  uint32_t sum = 0;
  for (uint32_t& o : offsets) sum += std::exchange(o, sum);
  offsets.push_back(sum);  // offsets[h] is where height h starts, h >= 1; offsets[0] (empty) = 0
  std::vector<uint32_t> next(offsets.begin(), offsets.end() - 1);
  order.assign(tree.innerCount, 0);
  for (uint32_t n = 0; n < tree.innerCount; ++n) order[next[height[n]]++] = n;
  offsets.erase(offsets.begin());  // from height 1
  return offsets;
}

BvhNode nodeOf(const Links& links, bool leaf) {
  BvhNode node;
  node.parent = links.parent;
  if (leaf) {
    node.primBegin = links.left;
    node.primCount = links.right;
  } else {
    node.left = links.left;
    node.right = links.right;
  }
  return node;
}

Bvh topologyOf(const std::vector<Links>& links, const std::vector<uint32_t>& primIds, uint32_t root,
               uint32_t innerCount) {
  Bvh out;
  out.frameCount = 0;
  out.root = root;
  out.primIds = primIds;
  out.nodes.resize(links.size());
  for (uint32_t n = 0; n < links.size(); ++n) out.nodes[n] = nodeOf(links[n], n >= innerCount);
  return out;
}

void checkReinsertionInput(const Bvh& tree, const PrimitiveBoxes& prims,
                           const ParallelReinsertionOptimizer::Config& config,
                           const ParallelReinsertionOptimizer::Parallel& parallel) {
  if (config.k < 0) throw tsah::ConfigError("ParallelReinsertionOptimizer: the exponent k must be >= 0");
  if (prims.frameCount == 0) throw tsah::DataError("ParallelReinsertionOptimizer: no frames");
  if (prims.primCount != tree.primCount() || prims.boxes.size() != std::size_t(prims.frameCount) * prims.primCount)
    throw tsah::DataError("ParallelReinsertionOptimizer: the tree holds " + std::to_string(tree.primCount()) +
                          " primitives, the boxes " + std::to_string(prims.primCount));
  if (!(parallel.candidateFraction > 0.0) || parallel.candidateFraction > 1.0)
    throw tsah::ConfigError("ParallelReinsertionOptimizer: candidateFraction must be in (0, 1]");
}

}  // namespace tsah::reinsertion
