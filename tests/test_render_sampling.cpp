// The renderer's per-pixel shutter times (tsah/render/sampling.hpp): in range, deterministic,
// stratified over consecutive pixels, and different per frame and seed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "tsah/render/sampling.hpp"

namespace {

std::vector<float> times(uint32_t seed, uint32_t frame, uint32_t first, uint32_t count) {
  std::vector<float> t;
  for (uint32_t p = first; p < first + count; ++p) t.push_back(tsah::pixelShutterTime({seed, frame, p}));
  return t;
}

}  // namespace

TEST(PixelShutterTime, InTheShutterAndDeterministic) {
  const std::vector<float> a = times(7, 3, 0, 100000);
  for (float t : a) {
    ASSERT_GE(t, 0.0f);
    ASSERT_LT(t, 1.0f);
  }
  EXPECT_EQ(a, times(7, 3, 0, 100000));
}

TEST(PixelShutterTime, ConsecutivePixelsAreStratified) {
  // Any n consecutive pixels: every one of n/4 equal parts of the shutter holds between 2 and 6
  // times (independent uniform times leave some parts empty at these sizes).
  for (uint32_t first : {0u, 12345u, 4000000000u}) {
    for (uint32_t n : {64u, 400u, 4096u}) {
      const std::vector<float> t = times(1, 0, first, n);
      std::vector<uint32_t> bins(n / 4, 0);
      for (float v : t) ++bins[std::min<std::size_t>(std::size_t(v * float(bins.size())), bins.size() - 1)];
      EXPECT_GE(*std::min_element(bins.begin(), bins.end()), 2u) << "first " << first << " n " << n;
      EXPECT_LE(*std::max_element(bins.begin(), bins.end()), 6u) << "first " << first << " n " << n;
    }
  }
}

TEST(PixelShutterTime, FrameAndSeedChangeTheTimes) {
  const std::vector<float> a = times(1, 0, 0, 256);
  EXPECT_NE(a, times(1, 1, 0, 256));
  EXPECT_NE(a, times(2, 0, 0, 256));
}
