#include "tsah/base/coordinates.hpp"

#include <cmath>
#include <cstdio>

namespace tsah {

std::size_t firstBadCoordinate(std::span<const float> positions) {
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!(std::fabs(positions[i]) <= kMaxCoordinate)) return i;  // NaN fails the comparison too
  return positions.size();
}

std::string describeBadCoordinate(float value) {
  if (!std::isfinite(value)) return "has a NaN or infinite coordinate";
  char text[128];
  std::snprintf(text, sizeof text, "has coordinate %g, beyond the supported magnitude %g", double(value),
                double(kMaxCoordinate));
  return std::string(text) + " (surface areas would overflow)";
}

}  // namespace tsah
