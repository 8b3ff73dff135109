#pragma once
// The property every point-cache input must have, shared by the libFuzzer targets (fuzz_pc2,
// fuzz_mdd) and by test_point_cache, which replays the seed corpora as ordinary tests.
//
// Decoding either throws tsah::FileError with a one-line message, or gives a cache whose counts
// agree, whose times increase and whose coordinates are finite, and which survives a round trip
// through the encoder (MDD: byte for byte, unless a rest-pose block was skipped; PC2: the same
// positions and times within the float precision of the header's start and rate).
#include <cmath>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "anim/animation.hpp"
#include "tsah/base/error.hpp"
#include "anim/point_cache.hpp"

namespace anim::fuzz {

// Nothing when the input behaves; otherwise what went wrong.
inline std::optional<std::string> pointCacheFinding(std::span<const uint8_t> bytes, PointCacheFormat format) {
  PointCache cache;
  try {
    cache = decodePointCache(bytes, "fuzz", format);
  } catch (const tsah::FileError& e) {
    if (std::string_view(e.what()).find('\n') != std::string_view::npos) return "error message is not one line";
    return std::nullopt;  // rejected with a clear error: fine
  }
  const std::size_t frames = cache.times.size();
  if (frames == 0 || cache.pointCount == 0) return "accepted an empty cache";
  if (cache.positions.size() != frames * cache.pointCount * 3) return "position count disagrees with the header";
  for (std::size_t i = 1; i < frames; ++i)
    if (!(cache.times[i] > cache.times[i - 1])) return "accepted non-increasing times";
  for (float v : cache.positions)
    if (!std::isfinite(v)) return "accepted a non-finite coordinate";
  // Round trip through the encoder, with a degenerate one-triangle topology (only positions matter).
  const Animation a({0, 0, 0}, cache.pointCount, cache.positions, cache.times, "fuzz");
  if (format == PointCacheFormat::Mdd) {
    if (!cache.skippedRestFrame && encodeMdd(a) != std::vector<uint8_t>(bytes.begin(), bytes.end()))
      return "MDD does not re-encode to the same bytes";
    return std::nullopt;
  }
  std::vector<uint8_t> again;
  try {
    again = encodePc2(a);
  } catch (const tsah::Error&) {
    return "PC2 sample times read from a file do not encode again";
  }
  const PointCache back = decodePc2(again, "fuzz-again");
  if (back.positions != cache.positions) return "PC2 positions change in a round trip";
  for (std::size_t i = 0; i < frames; ++i)
    if (std::fabs(back.times[i] - cache.times[i]) > 1e-3 * std::max(1.0, std::fabs(cache.times[i])))
      return "PC2 times change in a round trip";
  return std::nullopt;
}

}  // namespace anim::fuzz
