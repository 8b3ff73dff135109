// tsah/directed_rounding.hpp: the host implementation against the processor's own rounding modes
// (fesetround), over random operands of every magnitude, subnormals, overflow and infinities. The
// CUDA tests compare the device's hardware rounding with the same host code through the compressed
// wide BVH (quantized nodes and traversal decisions byte for byte).
#include <gtest/gtest.h>

#include <cfenv>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "tsah/layout/cwbvh_layout.hpp"
#include "tsah/core/directed_rounding.hpp"

namespace {

namespace r = tsah::rounding;

// Operations through volatile operands, so that they run under the current rounding mode.
float hwSub(float a, float b) {
  volatile float x = a, y = b;
  return x - y;
}
float hwMul(float a, float b) {
  volatile float x = a, y = b;
  return x * y;
}
float hwFma(float a, float b, float c) {
  volatile float x = a, y = b, z = c;
  return std::fma(float(x), float(y), float(z));
}

bool same(float a, float b) {
  if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b);
  uint32_t x, y;
  std::memcpy(&x, &a, 4);
  std::memcpy(&y, &b, 4);
  return x == y || (a == 0.0f && b == 0.0f);  // the sign of an exact zero sum may differ by mode
}

// Random floats over the whole range: random sign, exponent and mantissa bits, with some special values.
std::vector<float> operands(uint32_t count, std::mt19937& rng) {
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<float> v = {0.0f, -0.0f, 1.0f, -1.0f, 1e-45f, -1e-45f, 1.17549435e-38f, 3.4028235e38f,
                          -3.4028235e38f, inf, -inf, 0.1f, 1e30f, 1e-30f, 16777216.0f, 0.99999994f};
  for (uint32_t i = 0; i < count; ++i) {
    uint32_t bits = uint32_t(rng());
    if (i % 3 == 0) bits = (bits & 0x807fffffu) | ((100u + uint32_t(rng() % 56u)) << 23);  // near 1: sums that round
    float f;
    std::memcpy(&f, &bits, 4);
    if (std::isnan(f)) f = 1.5f;
    v.push_back(f);
  }
  return v;
}

struct RoundingMode {
  explicit RoundingMode(int mode) : saved(std::fegetround()) { std::fesetround(mode); }
  ~RoundingMode() { std::fesetround(saved); }
  int saved;
};

TEST(DirectedRounding, SumsAndProductsEqualTheProcessorsRoundingModes) {
  std::mt19937 rng(11);
  const std::vector<float> v = operands(3000, rng);
  uint32_t inexact = 0;  // cases where the two modes differ: the comparison is not vacuous
  for (std::size_t i = 0; i < v.size(); ++i) {
    for (int k = 0; k < 8; ++k) {
      const float a = v[i], b = k == 0 ? v[i] : v[rng() % v.size()];
      float down[2], up[2];
      {
        RoundingMode m(FE_DOWNWARD);
        down[0] = hwSub(a, b);
        down[1] = hwMul(a, b);
      }
      {
        RoundingMode m(FE_UPWARD);
        up[0] = hwSub(a, b);
        up[1] = hwMul(a, b);
      }
      ASSERT_TRUE(same(r::subDown(a, b), down[0])) << a << " - " << b;
      ASSERT_TRUE(same(r::subUp(a, b), up[0])) << a << " - " << b;
      ASSERT_TRUE(same(r::mulDown(a, b), down[1])) << a << " * " << b;
      ASSERT_TRUE(same(r::mulUp(a, b), up[1])) << a << " * " << b;
      ASSERT_TRUE(same(r::addDown(a, b), r::subDown(a, -b)));
      inexact += (down[0] != up[0]) + (down[1] != up[1]);
    }
  }
  EXPECT_GT(inexact, 10000u);
}

TEST(DirectedRounding, FusedMultiplyAddOfGridCoordinatesEqualsTheProcessors) {
  std::mt19937 rng(12);
  const std::vector<float> v = operands(2000, rng);
  uint32_t inexact = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    for (int k = 0; k < 6; ++k) {
      const float q = float(rng() % 256u), b = v[i], c = v[rng() % v.size()];
      float down, up;
      {
        RoundingMode m(FE_DOWNWARD);
        down = hwFma(q, b, c);
      }
      {
        RoundingMode m(FE_UPWARD);
        up = hwFma(q, b, c);
      }
      ASSERT_TRUE(same(r::fmaDown(q, b, c), down)) << q << " * " << b << " + " << c;
      ASSERT_TRUE(same(r::fmaUp(q, b, c), up)) << q << " * " << b << " + " << c;
      if (!std::isnan(down)) {
        ASSERT_LE(r::fmaDown(q, b, c), r::fmaUp(q, b, c)) << q << " * " << b << " + " << c;
      }
      inexact += down != up;
    }
  }
  EXPECT_GT(inexact, 2000u);
}

TEST(DirectedRounding, BoundsBracketTheRealResult) {
  // 1 + 2^-30 is not a float: down and up are the floats on either side, round-to-nearest is 1.
  const float tiny = std::ldexp(1.0f, -30);
  EXPECT_EQ(r::addDown(1.0f, tiny), 1.0f);
  EXPECT_EQ(r::addUp(1.0f, tiny), std::nextafter(1.0f, 2.0f));
  EXPECT_EQ(r::subDown(1.0f, tiny), std::nextafter(1.0f, 0.0f));
  EXPECT_EQ(r::subUp(1.0f, tiny), 1.0f);
  // Overflow: down stops at the largest float, up goes to infinity.
  EXPECT_EQ(r::mulDown(3e38f, 2.0f), std::numeric_limits<float>::max());
  EXPECT_EQ(r::mulUp(3e38f, 2.0f), std::numeric_limits<float>::infinity());
  EXPECT_EQ(r::fmaDown(255.0f, 3e38f, -1e30f), std::numeric_limits<float>::max());
  // 0 * inf is NaN, and NaN drops out of minNum / maxNum.
  EXPECT_TRUE(std::isnan(r::fmaDown(0.0f, std::numeric_limits<float>::infinity(), 1.0f)));
  EXPECT_EQ(r::maxNum(std::nanf(""), 2.0f), 2.0f);
  EXPECT_EQ(r::minNum(3.0f, std::nanf("")), 3.0f);
}

#if defined(__SIZEOF_FLOAT128__)
// The compressed BVH's slab line (cwbvh_layout.hpp): near bounds at or below and far bounds at or
// above the real distance (p + q * step - org) * invDir, computed exactly in binary128 (the
// operands are kept within 2^40 of each other, so the sum needs at most 65 bits and the product 89).
TEST(DirectedRounding, CwbvhSlabLineBracketsTheRealDistance) {
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::uniform_int_distribution<int> ex(-20, 20);
  uint32_t strict = 0;
  for (int i = 0; i < 200000; ++i) {
    const float scale = std::ldexp(1.0f, ex(rng));
    const float p = u(rng) * scale, org = u(rng) * scale * (i % 4 == 0 ? 1e-3f : 1.0f);
    const uint32_t e = 127u + uint32_t(ex(rng) / 2) - 8u;  // steps near scale / 256
    const float step = tsah::cwbvhStep(e);
    float dir = u(rng);
    if (i % 5 == 0) dir = 0.0f;
    const tsah::RayPrep prep = tsah::prepareSlabs(tsah::Ray{{org, 0, 0}, 0.0f, {dir, 1.0f, 1.0f}, 1.0f});
    const float inv = prep.invDir.x;
    const tsah::CwbvhSlabLine line = tsah::cwbvhSlabLine(p, step, org, inv, inv < 0.0f ? 1u : 0u);
    for (uint32_t q : {0u, 1u, 17u, 128u, 254u, 255u}) {
      const __float128 real = ((__float128)p + (__float128)q * step - (__float128)org) * (__float128)inv;
      const float g = float(q) + tsah::kCwbvhGridBias;
      const float lo = line.nearAt(g), hi = line.farAt(g);
      ASSERT_LE((__float128)lo, real) << "p " << p << " q " << q << " step " << step << " org " << org << " inv " << inv;
      ASSERT_GE((__float128)hi, real) << "p " << p << " q " << q << " step " << step << " org " << org << " inv " << inv;
      strict += (__float128)lo != real;
    }
  }
  EXPECT_GT(strict, 100000u);  // most distances are not floats: the bounds were really tested
}
#endif

}  // namespace
