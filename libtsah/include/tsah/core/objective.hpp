#pragma once
// What the builders, optimizers and collapses minimise: the paper's cost constants (Eq. 1), the
// T-SAH exponent k (Eq. 2-4) and the largest leaf the adaptive collapse may make. One value that
// travels whole from the command line or Python through the optimizer into the .tbvh header and
// from there into every layout's collapse (CPU bvh4/bvh8 and the GPU's compressed 8-wide tree).
#include <cstdint>

namespace tsah {

struct CostModel {
  float ct = 3.0f;  // cost of traversing an interior node
  float ci = 2.0f;  // cost of intersecting one triangle
  bool operator==(const CostModel&) const = default;
};

struct Objective {
  // Written out in the order k, cost, leaf size: a constructor rather than an aggregate, so that a
  // brace list in another order ({cost, leaf, k}) is refused instead of spread over the fields.
  Objective() = default;
  Objective(int k_, CostModel cost_, uint32_t maxLeafSize_) : k(k_), cost(cost_), maxLeafSize(maxLeafSize_) {}

  int k = 0;                  // T-SAH exponent: frame weights w_i = C_i^k (0: the plain average)
  CostModel cost;             // cT, cI (the paper's 3 and 2)
  uint32_t maxLeafSize = 8;   // largest leaf the collapse makes (a leaf of the optimizer is kept whole)

  // The limits every user of an objective relies on: 0 <= k <= kMaxK, cT and cI finite and > 0,
  // 1 <= maxLeafSize <= kMaxLeafSize. Throws tsah::ConfigError naming `who` and the field.
  void validate(const char* who = "objective") const;
  bool operator==(const Objective&) const = default;

  static constexpr int kMaxK = 16;                 // C_i^k of costs in the hundreds stays finite
  static constexpr uint32_t kMaxLeafSize = 256;    // the command line's --max-leaf limit
};

}  // namespace tsah
