#pragma once
// The coordinate limit every vertex position obeys, wherever positions come from (an imported
// animation, a caller's buffer handed to a runtime): one check, one message.
#include <cstddef>
#include <span>
#include <string>

namespace tsah {

// Largest coordinate magnitude accepted anywhere: a box of this extent still has a finite surface
// area in float (3 * (2e18)^2 << 3.4e38), with room for the sums of costs. Larger coordinates (or
// NaN/Inf) are refused, naming the first offending vertex.
inline constexpr float kMaxCoordinate = 1e18f;

// Index of the first coordinate that is NaN, infinite or beyond kMaxCoordinate; size() if none.
std::size_t firstBadCoordinate(std::span<const float> positions);
// "has a NaN or infinite coordinate" / "has coordinate 3e+38, beyond ..." for that coordinate.
std::string describeBadCoordinate(float value);

}  // namespace tsah
