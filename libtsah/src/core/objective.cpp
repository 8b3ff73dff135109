#include "tsah/core/objective.hpp"

#include <cmath>
#include <string>

#include "tsah/base/error.hpp"

namespace tsah {

void Objective::validate(const char* who) const {
  const std::string at = std::string(who) + ": ";
  if (k < 0 || k > kMaxK)
    throw ConfigError(at + "the T-SAH exponent k must be in 0.." + std::to_string(kMaxK) + ", not " + std::to_string(k));
  if (!std::isfinite(cost.ct) || !(cost.ct > 0.0f) || !std::isfinite(cost.ci) || !(cost.ci > 0.0f))
    throw ConfigError(at + "the cost constants cT and cI must be finite and positive");
  if (maxLeafSize < 1 || maxLeafSize > kMaxLeafSize)
    throw ConfigError(at + "the maximum leaf size must be in 1.." + std::to_string(kMaxLeafSize) + ", not " +
                      std::to_string(maxLeafSize));
}

}  // namespace tsah
