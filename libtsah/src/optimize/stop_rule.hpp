#pragma once
// The optimizers' stop rule (sequential batches and parallel rounds alike): a batch improves when
// it lowers the best cost so far by at least the fraction minImprovement; the run stalls after
// `patience` batches in a row that do not.
#include <algorithm>
#include <cstdint>

namespace tsah {

class StallCounter {
 public:
  StallCounter(double initialCost, double minImprovement, uint32_t patience)
      : best_(initialCost), minImprovement_(minImprovement), patience_(patience) {}

  // Records the cost after a batch; true once `patience` batches in a row did not improve.
  bool stalledAfter(double cost) {
    without_ = cost < best_ * (1.0 - minImprovement_) ? 0 : without_ + 1;
    best_ = std::min(best_, cost);
    return without_ >= patience_;
  }

 private:
  double best_;
  double minImprovement_;
  uint32_t patience_;
  uint32_t without_ = 0;
};

}  // namespace tsah
