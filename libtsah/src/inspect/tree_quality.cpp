#include "tsah/inspect/tree_quality.hpp"

#include <algorithm>
#include <limits>

namespace tsah {

namespace {

// Added to both relative areas of a growth ratio, so a box without area (a flat leaf) gives a
// large finite ratio instead of a division by zero.
constexpr double kRelativeAreaFloor = 1e-12;

}  // namespace

std::vector<uint32_t> nodeDepths(const Bvh& bvh) {
  std::vector<uint32_t> depth(bvh.nodes.size(), kInvalidIndex);
  if (bvh.nodes.empty()) return depth;
  std::vector<uint32_t> stack{bvh.root};
  depth[bvh.root] = 0;
  while (!stack.empty()) {
    const BvhNode& n = bvh.nodes[stack.back()];
    const uint32_t d = depth[stack.back()];
    stack.pop_back();
    if (n.isLeaf()) continue;
    for (uint32_t child : {n.left, n.right}) {
      depth[child] = d + 1;
      stack.push_back(child);
    }
  }
  return depth;
}

TreeShape treeShape(const Bvh& bvh) {
  TreeShape s;
  const std::vector<uint32_t> depth = nodeDepths(bvh);
  s.smallestLeaf = std::numeric_limits<uint32_t>::max();
  for (uint32_t i = 0; i < bvh.nodeCount(); ++i) {
    if (depth[i] == kInvalidIndex) continue;
    const BvhNode& n = bvh.nodes[i];
    if (!n.isLeaf()) {
      ++s.innerCount;
      continue;
    }
    ++s.leafCount;
    s.primCount += n.primCount;
    s.depth = std::max(s.depth, depth[i]);
    s.smallestLeaf = std::min(s.smallestLeaf, n.primCount);
    s.largestLeaf = std::max(s.largestLeaf, n.primCount);
    if (s.leavesOfSize.size() <= n.primCount) s.leavesOfSize.resize(n.primCount + 1, 0);
    ++s.leavesOfSize[n.primCount];
  }
  if (s.leafCount == 0) s.smallestLeaf = 0;
  s.meanLeafSize = s.leafCount ? double(s.primCount) / s.leafCount : 0.0;
  return s;
}

FrameBoxes frameBoxes(const Bvh& bvh, std::span<const Aabb> primBoxes, const CostModel& model) {
  FrameCostEvaluator evaluator(bvh, model);
  FrameBoxes out;
  out.cost = evaluator.costParts(primBoxes);
  out.boxes.assign(evaluator.nodeBoxes().begin(), evaluator.nodeBoxes().end());
  out.costShare.assign(bvh.nodes.size(), 0.0);
  const double total = out.cost.innerTerm + out.cost.leafTerm;
  const std::vector<uint32_t> depth = nodeDepths(bvh);
  for (uint32_t i = 0; i < bvh.nodeCount(); ++i)
    if (depth[i] != kInvalidIndex && total > 0.0)
      out.costShare[i] = nodeCostTerm(model, out.boxes[i].area(), bvh.nodes[i].primCount) / total;
  return out;
}

TreeQuality evaluateTreeQuality(const Bvh& bvh, const FrameSource& frames, const CostModel& model) {
  TreeQuality q;
  if (bvh.nodes.empty() || frames.frameCount == 0) return q;
  const std::vector<uint32_t> depth = nodeDepths(bvh);
  FrameCostEvaluator evaluator(bvh, model);
  std::vector<Aabb> prims(frames.primCount);
  std::vector<double> smallest(bvh.nodes.size(), std::numeric_limits<double>::infinity());
  std::vector<double> largest(bvh.nodes.size(), 0.0);
  const BvhNode& root = bvh.nodes[bvh.root];
  std::array<double, 2> firstChildArea{0.0, 0.0};
  for (uint32_t f = 0; f < frames.frameCount; ++f) {
    frames.fill(f, prims);
    FrameQuality fq;
    fq.cost = evaluator.costParts(prims);
    const std::span<const Aabb> boxes = evaluator.nodeBoxes();
    const double rootArea = boxes[bvh.root].area();
    double leafArea = 0.0, depthSum = 0.0, sizeSum = 0.0;
    for (uint32_t i = 0; i < bvh.nodeCount(); ++i) {
      if (depth[i] == kInvalidIndex) continue;
      const double area = boxes[i].area();
      const double relative = rootArea > 0.0 ? area / rootArea : 1.0;
      smallest[i] = std::min(smallest[i], relative);
      largest[i] = std::max(largest[i], relative);
      if (bvh.nodes[i].isLeaf()) {
        leafArea += area;
        depthSum += area * depth[i];
        sizeSum += area * bvh.nodes[i].primCount;
      }
    }
    if (leafArea > 0.0) {
      fq.meanLeafDepth = depthSum / leafArea;
      fq.meanLeafSize = sizeSum / leafArea;
    }
    if (!root.isLeaf()) {
      const std::array<uint32_t, 2> children{root.left, root.right};
      for (int c = 0; c < 2; ++c) {
        const double area = boxes[children[c]].area();
        if (f == 0) firstChildArea[c] = area;
        fq.rootChildGrowth[c] = firstChildArea[c] > 0.0 ? area / firstChildArea[c] : (area > 0.0 ? std::numeric_limits<double>::infinity() : 1.0);
      }
    }
    q.frames.push_back(fq);
  }
  q.nodeGrowth.assign(bvh.nodes.size(), 1.0);
  for (uint32_t i = 0; i < bvh.nodeCount(); ++i)
    if (depth[i] != kInvalidIndex)
      q.nodeGrowth[i] = (largest[i] + kRelativeAreaFloor) / (smallest[i] + kRelativeAreaFloor);
  return q;
}

}  // namespace tsah
