// The host side shared by every reinsertion backend (reinsertion_rounds.hpp): the optimizer's node
// numbering, the first interior boxes, the topology back as a Bvh, the input checks.
#include <stdexcept>
#include <string>

#include "tsah/reinsertion_rounds.hpp"

namespace tsah::reinsertion {

NumberedTree numberTree(const Bvh& tree) {
  if (tree.nodes.empty()) throw std::invalid_argument("ParallelReinsertionOptimizer: empty tree");
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

std::vector<Aabb> innerBoxesOf(const NumberedTree& tree, const PrimitiveBoxes& prims) {
  const uint32_t frames = prims.frameCount;
  std::vector<Aabb> boxes(std::size_t(tree.innerCount) * frames);
  std::vector<Aabb> buffer(frames);
  const std::vector<float> noFactors(frames, 0.0f);
  uint32_t root = tree.root;
  // Interior nodes are numbered children first, so one ascending pass refits every node after its
  // children. The view's area array is a dummy: the areas come with the first weights.
  std::vector<float> area(tree.nodeCount, 0.0f);
  const TreeView t{const_cast<Links*>(tree.links.data()), boxes.data(), area.data(), prims.boxes.data(),
                   tree.primIds.data(), noFactors.data(), &root, frames, tree.innerCount, tree.nodeCount,
                   prims.primCount, false};
  for (uint32_t n = 0; n < tree.innerCount; ++n) refitNode(t, n, buffer.data());
  return boxes;
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
  if (config.k < 0) throw std::invalid_argument("ParallelReinsertionOptimizer: the exponent k must be >= 0");
  if (prims.frameCount == 0) throw std::invalid_argument("ParallelReinsertionOptimizer: no frames");
  if (prims.primCount != tree.primCount() || prims.boxes.size() != std::size_t(prims.frameCount) * prims.primCount)
    throw std::invalid_argument("ParallelReinsertionOptimizer: the tree holds " + std::to_string(tree.primCount()) +
                                " primitives, the boxes " + std::to_string(prims.primCount));
  if (!(parallel.candidateFraction > 0.0) || parallel.candidateFraction > 1.0)
    throw std::invalid_argument("ParallelReinsertionOptimizer: candidateFraction must be in (0, 1]");
}

}  // namespace tsah::reinsertion
