#include "tsah/layout/motion_blur.hpp"

#include <cmath>

#include "tsah/base/error.hpp"

namespace tsah::motion {

void checkKeyTimes(std::span<const float> keyTimes, std::size_t positionSets, const std::string& who) {
  if (keyTimes.empty()) throw tsah::ConfigError(who + "a shutter needs at least one key");
  if (keyTimes.size() != positionSets)
    throw tsah::ConfigError(who + std::to_string(keyTimes.size()) + " key times for " + std::to_string(positionSets) +
                            " sets of positions");
  for (float k : keyTimes)
    if (!std::isfinite(k) || k < 0.0f || k > 1.0f)
      throw tsah::ConfigError(who + "key time " + std::to_string(k) + " is outside [0, 1]");
  if (keyTimes.size() == 1) return;
  if (keyTimes.front() != 0.0f || keyTimes.back() != 1.0f)
    throw tsah::ConfigError(who + "the shutter's key times must run from 0 to 1");
  for (std::size_t k = 1; k < keyTimes.size(); ++k)
    if (!(keyTimes[k] > keyTimes[k - 1]))
      throw tsah::ConfigError(who + "the shutter's key times must increase (key " + std::to_string(k) + ")");
}

}  // namespace tsah::motion
