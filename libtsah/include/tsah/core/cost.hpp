#pragma once
// The paper's cost model (Section 4): the per-frame SAH cost of a tree normalized by the root area
// (Eq. 1) and the temporal SAH over several frames (Eq. 2-4).
//
//   C_i     = (cT * sum_inner S_N(i) + cI * sum_leaves j_N * S_N(i)) / S_i
//   C~^k    = sum_i C_i^(k+1) / sum_i C_i^k        (k = 0: the plain average)
//
// A frame whose root box has zero area (every triangle collapsed to one point or line) has no
// meaningful area ratios; its cost is defined as the limit of a uniformly shrinking scene, where
// every ray that reaches the root visits every node: cT * inner + cI * primitives.
#include <cstdint>
#include <span>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/core/objective.hpp"

namespace tsah {

// Eq. 1 split into its two sums: C_i = (innerTerm + leafTerm) / rootArea. For a frame whose root has
// no area the terms are cT * inner and cI * primitives and rootArea is 1 (see above).
struct CostParts {
  double innerTerm = 0.0;  // cT * sum of interior node areas
  double leafTerm = 0.0;   // cI * sum over leaves of primitives * area
  double rootArea = 1.0;
  double inner() const { return innerTerm / rootArea; }
  double leaves() const { return leafTerm / rootArea; }
  double total() const { return (innerTerm + leafTerm) / rootArea; }
};

// One node's term of the numerator of Eq. 1 (its share of a frame's cost is term / (innerTerm +
// leafTerm)): cT * area for an interior node, cI * primitives * area for a leaf.
inline double nodeCostTerm(const CostModel& model, double area, uint32_t leafPrimCount) {
  return leafPrimCount > 0 ? double(model.ci) * double(leafPrimCount) * area : double(model.ct) * area;
}

// Eq. 1 for one frame of the boxes stored in the tree (frame < bvh.frameCount).
double frameCost(const Bvh& bvh, uint32_t frame, const CostModel& model = {});
// Eq. 1 for every frame stored in the tree.
std::vector<double> frameCosts(const Bvh& bvh, const CostModel& model = {});

// Eq. 3: the T-SAH cost of per-frame costs with exponent k (k >= 0). 0 for no frames.
double temporalCost(std::span<const double> frameCosts, int k);
// The frame weights of Eq. 2, w_i = C_i^k, scaled so that they sum to 1 (all equal for k = 0 or
// when every cost is 0).
std::vector<double> temporalWeights(std::span<const double> frameCosts, int k);

// The per-frame terms an optimizer tracks while it changes a tree: S_i (root area), the interior and
// leaf area sums of Eq. 1, C_i, and the factors of the weighted area A(B) = sum_i areaFactor_i *
// area(B_i), areaFactor_i = (w_i / W) / S_i. Shared by the sequential and the parallel optimizer.
struct FrameCostTerms {
  std::vector<double> rootArea, innerArea, leafArea, frameCost;
  std::vector<float> areaFactor;

  void reset(uint32_t frames);  // every term 0 for `frames` frames
  // C_i of every frame from the three area sums; returns C~^k (Eq. 3).
  double updateFrameCosts(const CostModel& model, uint64_t innerCount, uint64_t primCount, int k);
  // The weights w_i of the current C_i (temporalWeights) and the area factors made from them;
  // returns the weights.
  std::vector<double> updateAreaFactors(int k);
};

// The cost of one frame of the animation for a fixed tree topology: refits the tree to that frame's
// primitive boxes (in a buffer owned by the evaluator) and evaluates Eq. 1. Works for any frame,
// not only the representative ones stored in the tree. Allocates only on construction; one
// evaluator per thread.
class FrameCostEvaluator {
 public:
  explicit FrameCostEvaluator(const Bvh& bvh, CostModel model = {});

  // primBoxes: one box per primitive (bvh.primCount() of them), indexed by primitive id.
  double cost(std::span<const Aabb> primBoxes) { return costParts(primBoxes).total(); }
  // The same with its interior and leaf sums apart.
  CostParts costParts(std::span<const Aabb> primBoxes);
  // The node boxes of the last cost() call, indexed by node.
  std::span<const Aabb> nodeBoxes() const { return boxes_; }

 private:
  struct Step {
    uint32_t node;
    uint32_t a, b;       // children, or the primitive range [a, a+b) for a leaf
    bool leaf;
  };
  const Bvh* bvh_;
  CostModel model_;
  std::vector<Step> postOrder_;  // children before parents
  std::vector<Aabb> boxes_;
  uint32_t innerCount_ = 0;
  uint64_t primTotal_ = 0;
};

}  // namespace tsah
