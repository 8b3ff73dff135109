#include "tsah/core/cost.hpp"

#include <algorithm>
#include <cmath>

#include "tsah/base/error.hpp"
#include "tsah/core/cost_terms.hpp"

namespace tsah {

namespace {

// cT * inner + cI * primitives: the cost of a frame whose root has no area (see cost.hpp), as parts
// over a unit root area (the same value cost::frameCost gives).
CostParts degenerateFrameCost(uint64_t innerCount, uint64_t primCount, const CostModel& model) {
  return {double(model.ct) * double(innerCount), double(model.ci) * double(primCount), 1.0};
}

}  // namespace

double frameCost(const Bvh& bvh, uint32_t frame, const CostModel& model) {
  if (bvh.nodes.empty()) return 0.0;
  if (frame >= bvh.frameCount) throw tsah::ConfigError("frameCost: frame index out of range");
  double inner = 0.0, leaves = 0.0;
  uint64_t innerCount = 0, primCount = 0;
  for (uint32_t n = 0; n < bvh.nodeCount(); ++n) {
    const BvhNode& node = bvh.nodes[n];
    const double area = bvh.box(n, frame).area();
    if (node.isLeaf()) {
      leaves += area * node.primCount;
      primCount += node.primCount;
    } else {
      inner += area;
      ++innerCount;
    }
  }
  return cost::frameCost(model.ct, model.ci, inner, leaves, bvh.box(bvh.root, frame).area(), innerCount, primCount);
}

std::vector<double> frameCosts(const Bvh& bvh, const CostModel& model) {
  std::vector<double> costs(bvh.frameCount);
  for (uint32_t f = 0; f < bvh.frameCount; ++f) costs[f] = frameCost(bvh, f, model);
  return costs;
}

double temporalCost(std::span<const double> frameCosts, int k) {
  if (k < 0) throw tsah::ConfigError("temporalCost: the exponent k must be >= 0");
  return cost::temporalCost(frameCosts.data(), static_cast<uint32_t>(frameCosts.size()), k);
}

std::vector<double> temporalWeights(std::span<const double> frameCosts, int k) {
  if (k < 0) throw tsah::ConfigError("temporalWeights: the exponent k must be >= 0");
  std::vector<double> weights(frameCosts.size(), 0.0);
  if (frameCosts.empty()) return weights;
  double largest = 0.0;
  for (double c : frameCosts) largest = std::max(largest, c);
  double total = 0.0;
  for (std::size_t i = 0; i < frameCosts.size(); ++i) {
    weights[i] = (k == 0 || !(largest > 0.0)) ? 1.0 : cost::integerPower(frameCosts[i] / largest, k);
    total += weights[i];
  }
  if (!(total > 0.0)) {  // every frame cost 0 with k > 0: weigh them equally
    for (double& w : weights) w = 1.0;
    total = double(weights.size());
  }
  for (double& w : weights) w /= total;
  return weights;
}

void FrameCostTerms::reset(uint32_t frames) {
  rootArea.assign(frames, 0.0);
  innerArea.assign(frames, 0.0);
  leafArea.assign(frames, 0.0);
  frameCost.assign(frames, 0.0);
  areaFactor.assign(frames, 0.0f);
}

double FrameCostTerms::updateFrameCosts(const CostModel& model, uint64_t innerCount, uint64_t primCount, int k) {
  for (std::size_t f = 0; f < frameCost.size(); ++f)
    frameCost[f] = cost::frameCost(model.ct, model.ci, innerArea[f], leafArea[f], rootArea[f], innerCount, primCount);
  return temporalCost(frameCost, k);
}

std::vector<double> FrameCostTerms::updateAreaFactors(int k) {
  std::vector<double> w = temporalWeights(frameCost, k);
  for (std::size_t f = 0; f < frameCost.size(); ++f) areaFactor[f] = cost::areaFactor(w[f], rootArea[f]);
  return w;
}

FrameCostEvaluator::FrameCostEvaluator(const Bvh& bvh, CostModel model) : bvh_(&bvh), model_(model) {
  boxes_.resize(bvh.nodes.size());
  if (bvh.nodes.empty()) return;
  postOrder_.reserve(bvh.nodes.size());
  std::vector<uint32_t> stack{bvh.root};
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    const BvhNode& node = bvh.nodes[n];
    if (node.isLeaf()) {
      postOrder_.push_back({n, node.primBegin, node.primCount, true});
      primTotal_ += node.primCount;
    } else {
      postOrder_.push_back({n, node.left, node.right, false});
      ++innerCount_;
      stack.push_back(node.left);
      stack.push_back(node.right);
    }
  }
  // Reversed pre-order visits every child before its parent.
  std::reverse(postOrder_.begin(), postOrder_.end());
}

CostParts FrameCostEvaluator::costParts(std::span<const Aabb> primBoxes) {
  if (postOrder_.empty()) return {0.0, 0.0, 1.0};
  if (primBoxes.size() != bvh_->primIds.size())
    throw tsah::DataError("FrameCostEvaluator: expected " + std::to_string(bvh_->primIds.size()) +
                          " primitive boxes, got " + std::to_string(primBoxes.size()));
  const uint32_t* primIds = bvh_->primIds.data();
  double inner = 0.0, leaves = 0.0;
  for (const Step& s : postOrder_) {
    Aabb box;
    if (s.leaf) {
      for (uint32_t i = 0; i < s.b; ++i) box.extend(primBoxes[primIds[s.a + i]]);
      leaves += double(box.area()) * s.b;
    } else {
      box = merge(boxes_[s.a], boxes_[s.b]);
      inner += box.area();
    }
    boxes_[s.node] = box;
  }
  const double rootArea = boxes_[bvh_->root].area();
  if (!(rootArea > 0.0)) return degenerateFrameCost(innerCount_, primTotal_, model_);
  return {model_.ct * inner, model_.ci * leaves, rootArea};
}

}  // namespace tsah
