// tsah/layout/motion_blur.hpp: the shutter's key times, the segment of a ray's time, and the
// conservativeness of the lerped box (it contains every vertex lerped with the same f, under
// round-to-nearest and under any rounding of the vertex's lerp).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include "tsah/core/directed_rounding.hpp"
#include "tsah/layout/motion_blur.hpp"

namespace {

namespace m = tsah::motion;
using tsah::Aabb;
using tsah::Vec3;

const std::vector<double> kKeyframes{0.0, 1.0, 2.0, 3.0};

TEST(MotionBlurKeys, ShutterInsideOneSegmentHasTwoKeys) {
  EXPECT_EQ(m::shutterKeys(kKeyframes, 1.25, 1.75), (std::vector<double>{1.25, 1.75}));
}

TEST(MotionBlurKeys, ShutterSpanningKeyframesKeepsThoseStrictlyInside) {
  EXPECT_EQ(m::shutterKeys(kKeyframes, 0.5, 2.5), (std::vector<double>{0.5, 1.0, 2.0, 2.5}));
  // A shutter ending on a keyframe does not repeat it.
  EXPECT_EQ(m::shutterKeys(kKeyframes, 1.0, 2.0), (std::vector<double>{1.0, 2.0}));
}

TEST(MotionBlurKeys, ShutterAtTheEndsOfTheAnimation) {
  EXPECT_EQ(m::shutterKeys(kKeyframes, 0.0, 0.5), (std::vector<double>{0.0, 0.5}));
  EXPECT_EQ(m::shutterKeys(kKeyframes, 2.5, 3.0), (std::vector<double>{2.5, 3.0}));
  EXPECT_EQ(m::shutterKeys(kKeyframes, 0.0, 3.0), (std::vector<double>{0.0, 1.0, 2.0, 3.0}));
}

TEST(MotionBlurKeys, ClosedShutterIsOneKey) {
  EXPECT_EQ(m::shutterKeys(kKeyframes, 1.0, 1.0), (std::vector<double>{1.0}));
  EXPECT_EQ(m::keyFractions(std::vector<double>{1.0}), (std::vector<float>{0.0f}));
}

// A shutter that closes within double rounding of a keyframe: the keyframe's float fraction would
// equal the close's 1, so it is not a key of its own, and the runtime accepts the keys (strictly
// increasing fractions). Near the open the fraction is a tiny float above 0: the keyframe stays.
TEST(MotionBlurKeys, KeyframesWithinFloatRoundingOfAnotherKeyAreLeftOut) {
  const double justAfter = std::nextafter(2.0, 3.0), justBefore = std::nextafter(1.0, 0.0);
  EXPECT_EQ(m::shutterKeys(kKeyframes, 1.5, justAfter), (std::vector<double>{1.5, justAfter}));
  EXPECT_EQ(m::shutterKeys(kKeyframes, justBefore, 1.5), (std::vector<double>{justBefore, 1.0, 1.5}));
  EXPECT_EQ(m::shutterKeys(kKeyframes, 0.5, 2.0 + 1e-9), (std::vector<double>{0.5, 1.0, 2.0 + 1e-9}));
  EXPECT_EQ(m::shutterKeys(kKeyframes, 0.5, 2.0 + 1e-6), (std::vector<double>{0.5, 1.0, 2.0, 2.0 + 1e-6}));
  for (const auto& [open, close] : {std::pair{1.5, justAfter}, std::pair{justBefore, 1.5}, std::pair{0.5, 2.0 + 1e-9}}) {
    const std::vector<double> keys = m::shutterKeys(kKeyframes, open, close);
    const std::vector<float> f = m::keyFractions(keys);
    EXPECT_NO_THROW(m::checkKeyTimes(f, keys.size(), "test: "));
  }
}

TEST(MotionBlurKeys, FractionsRunFromZeroToOne) {
  const std::vector<float> f = m::keyFractions(m::shutterKeys(kKeyframes, 0.5, 2.5));
  EXPECT_EQ(f, (std::vector<float>{0.0f, 0.25f, 0.75f, 1.0f}));
}

TEST(MotionBlurSegment, PicksTheLastKeyAtOrBelowTau) {
  const float keys[] = {0.0f, 0.25f, 0.75f, 1.0f};
  m::Segment s = m::segmentAt(keys, 4, 0.0f);
  EXPECT_EQ(s.index, 0);
  EXPECT_EQ(s.f, 0.0f);
  s = m::segmentAt(keys, 4, 0.25f);  // on a key: the segment starting there
  EXPECT_EQ(s.index, 1);
  EXPECT_EQ(s.f, 0.0f);
  s = m::segmentAt(keys, 4, 0.5f);
  EXPECT_EQ(s.index, 1);
  EXPECT_FLOAT_EQ(s.f, 0.5f);
  s = m::segmentAt(keys, 4, 1.0f);  // the close: the end of the last segment
  EXPECT_EQ(s.index, 2);
  EXPECT_EQ(s.f, 1.0f);
}

TEST(MotionBlurSegment, ClampsTimesOutsideTheShutter) {
  const float keys[] = {0.0f, 0.5f, 1.0f};
  m::Segment s = m::segmentAt(keys, 3, -0.5f);
  EXPECT_EQ(s.index, 0);
  EXPECT_EQ(s.f, 0.0f);
  s = m::segmentAt(keys, 3, 2.0f);
  EXPECT_EQ(s.index, 1);
  EXPECT_EQ(s.f, 1.0f);
  s = m::segmentAt(keys, 3, std::nanf(""));
  EXPECT_EQ(s.index, 0);
  EXPECT_EQ(s.f, 0.0f);
  const float one[] = {0.0f};
  s = m::segmentAt(one, 1, 0.7f);
  EXPECT_EQ(s.index, 0);
  EXPECT_EQ(s.f, 0.0f);
}

// Interval bounds [lower, upper] on the vertex's lerp (1 - f) * a + f * b under any rounding of
// each operation (directed rounding of each step; every step is monotone in its rounded input).
struct Bounds {
  float lower, upper;
};
Bounds lerpBounds(float a, float b, float f) {
  namespace r = tsah::rounding;
  const float gl = r::subDown(1.0f, f), gh = r::subUp(1.0f, f);
  const float pl = std::fmin(r::mulDown(gl, a), r::mulDown(gh, a));
  const float ph = std::fmax(r::mulUp(gl, a), r::mulUp(gh, a));
  return {r::addDown(pl, r::mulDown(f, b)), r::addUp(ph, r::mulUp(f, b))};
}

// The lerped box a traversal tests: lerpBox of the two keys, or (prepadded) the plain lerp of the
// keys pre-padded over both (the smallest pad a frame of those keys gets; the GPU layout moves such
// boxes, test_blurred_node.cpp).
Aabb lerpedBox(const Aabb& b0, const Aabb& b1, float f, bool prepadded) {
  if (!prepadded) return m::lerpBox(b0, b1, f);
  const Vec3 mag = m::foldMagnitudes(b1, m::foldMagnitudes(b0, Vec3{0.0f, 0.0f, 0.0f}));
  const Aabb a = m::prepadBox(b0, mag), b = m::prepadBox(b1, mag);
  return {m::lerpVertex(a.lo, b.lo, f), m::lerpVertex(a.hi, b.hi, f)};
}

// Boxes at two keys around random vertices of the given magnitude, then random f: the lerped box
// contains the vertex lerped with f (round-to-nearest) and every directed rounding of it.
void checkContainment(float magnitude, uint32_t seed, bool tightBoxes, bool prepadded = false) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-magnitude, magnitude);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (int trial = 0; trial < 20000; ++trial) {
    const Vec3 v0{coord(rng), coord(rng), coord(rng)};
    const Vec3 v1{coord(rng), coord(rng), coord(rng)};
    Aabb b0, b1;
    b0.extend(v0);
    b1.extend(v1);
    if (!tightBoxes) {  // other vertices widen the boxes
      b0.extend(Vec3{coord(rng), coord(rng), coord(rng)});
      b1.extend(Vec3{coord(rng), coord(rng), coord(rng)});
    }
    // f near the ends too, where the rounding of f * (b - a) matters most.
    float f = unit(rng);
    if (trial % 4 == 1) f = 1.0f - f * 1e-6f;
    if (trial % 4 == 2) f = f * 1e-6f;
    const Aabb box = lerpedBox(b0, b1, f, prepadded);
    const Vec3 v = m::lerpVertex(v0, v1, f);
    for (int a = 0; a < 3; ++a) {
      ASSERT_LE(box.lo[a], v[a]) << "axis " << a << " f " << f;
      ASSERT_GE(box.hi[a], v[a]) << "axis " << a << " f " << f;
      const Bounds bounds = lerpBounds(v0[a], v1[a], f);
      ASSERT_LE(box.lo[a], bounds.lower);
      ASSERT_GE(box.hi[a], bounds.upper);
      // The exact lerp of the vertex (double holds it to well within a float ulp).
      const double exact = v0[a] + double(f) * (double(v1[a]) - v0[a]);
      ASSERT_LE(box.lo[a], exact);
      ASSERT_GE(box.hi[a], exact);
    }
  }
}

TEST(MotionBlurLerp, BoxContainsLerpedVertexUnderRounding) {
  checkContainment(1.0f, 1, true);
  checkContainment(1e4f, 2, true);
  checkContainment(1e-30f, 3, true);
  checkContainment(1e30f, 4, true);
  checkContainment(100.0f, 5, false);
}

// The GPU blurred layout's boxes: pre-padded once per key, lerped with no pad at the ray's time.
TEST(MotionBlurLerp, PrepaddedBoxContainsLerpedVertexUnderRounding) {
  checkContainment(1.0f, 11, true, true);
  checkContainment(1e4f, 12, true, true);
  checkContainment(1e-30f, 13, true, true);
  checkContainment(1e30f, 14, true, true);
  checkContainment(100.0f, 15, false, true);
}

// Without the pad the lerped box misses some lerped vertices: the pad is needed, not decoration.
TEST(MotionBlurLerp, UnpaddedLerpWouldMissVertices) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coord(-1000.0f, 1000.0f);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  int misses = 0;
  for (int trial = 0; trial < 20000 && misses == 0; ++trial) {
    const float a = coord(rng), b = coord(rng), f = unit(rng);
    if (m::lerp(a, b, f) > lerpBounds(a, b, f).lower) ++misses;
  }
  EXPECT_GT(misses, 0);
}

// A node's boxes at two keys, apart: [0,1]x[1,2]x[2,3] and [4,5]x[5,6]x[6,7].
std::pair<Aabb, Aabb> twoKeyBoxes() {
  Aabb b0, b1;
  b0.extend(Vec3{0.0f, 1.0f, 2.0f});
  b0.extend(Vec3{1.0f, 2.0f, 3.0f});
  b1.extend(Vec3{4.0f, 5.0f, 6.0f});
  b1.extend(Vec3{5.0f, 6.0f, 7.0f});
  return {b0, b1};
}

TEST(MotionBlurLerp, EndsAreTheKeyBoxesPadded) {
  const auto [b0, b1] = twoKeyBoxes();
  const Aabb at0 = m::lerpBox(b0, b1, 0.0f), at1 = m::lerpBox(b0, b1, 1.0f);
  EXPECT_TRUE(at0.contains(b0));
  EXPECT_TRUE(at1.contains(b1));
  EXPECT_NEAR(at0.lo.x, 0.0f, 1e-4f);
  EXPECT_NEAR(at1.hi.z, 7.0f, 1e-4f);
  // The vertex lerp is exact at the ends: a segment's ends are its keys bit for bit.
  const Vec3 a{0.1f, -3.7f, 1e7f}, b{-2.3f, 5.9f, 3e-5f};
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(m::lerpVertex(a, b, 0.0f)[i], a[i]);
    EXPECT_EQ(m::lerpVertex(a, b, 1.0f)[i], b[i]);
  }
}

// Pre-padding widens each side outward by the pad of its axis's largest magnitude over the keys;
// an empty box stays empty through the pad and the lerp.
TEST(MotionBlurLerp, PrepaddedBoxesWidenOutwardAndEmptyBoxesStayEmpty) {
  const auto [b0, b1] = twoKeyBoxes();
  const Vec3 mag = m::foldMagnitudes(b1, m::foldMagnitudes(b0, Vec3{0.0f, 0.0f, 0.0f}));
  EXPECT_EQ(mag.x, 5.0f);
  EXPECT_EQ(mag.z, 7.0f);
  const Aabb padded = m::prepadBox(b0, mag);
  EXPECT_TRUE(padded.contains(b0));
  EXPECT_LT(padded.lo.x, b0.lo.x);
  EXPECT_GT(padded.hi.z, b0.hi.z);
  const Aabb empty;
  EXPECT_TRUE(m::prepadBox(empty, m::foldMagnitudes(empty, Vec3{0.0f, 0.0f, 0.0f})).empty());
  EXPECT_TRUE(lerpedBox(empty, empty, 0.37f, true).empty());
}

// Random boxes of a node at two keys and random child boxes inside them (every third trial the
// node's own boxes, the worst case): segmentBounds holds every child's lerped box at random f.
void checkSegmentBounds(float magnitude, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-magnitude, magnitude);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const auto boxOf = [&] {
    Aabb b;
    b.extend(Vec3{coord(rng), coord(rng), coord(rng)});
    b.extend(Vec3{coord(rng), coord(rng), coord(rng)});
    return b;
  };
  const auto inside = [&](const Aabb& b) {
    Aabb c;
    for (int k = 0; k < 2; ++k) {
      Vec3 p;
      for (int a = 0; a < 3; ++a) p[a] = b.lo[a] + unit(rng) * (b.hi[a] - b.lo[a]);
      c.extend(p);
    }
    return c;
  };
  for (int trial = 0; trial < 20000; ++trial) {
    const Aabb b0 = boxOf(), b1 = boxOf();
    const bool own = trial % 3 == 0;
    const Aabb c0 = own ? b0 : inside(b0), c1 = own ? b1 : inside(b1);
    ASSERT_TRUE(b0.contains(c0) && b1.contains(c1));
    float f = unit(rng);
    if (trial % 4 == 1) f = 1.0f - f * 1e-6f;
    if (trial % 4 == 2) f = f * 1e-6f;
    const Aabb bound = m::segmentBounds(b0, b1), child = m::lerpBox(c0, c1, f);
    for (int a = 0; a < 3; ++a) {
      ASSERT_LE(bound.lo[a], child.lo[a]) << "axis " << a << " f " << f;
      ASSERT_GE(bound.hi[a], child.hi[a]) << "axis " << a << " f " << f;
    }
  }
}

// The box the wide kernels test once per ray before the root's children (WideMotionFrame::rootBounds).
TEST(MotionBlurLerp, SegmentBoundsHoldEveryChildsLerpedBox) {
  checkSegmentBounds(1.0f, 11);
  checkSegmentBounds(1e4f, 12);
  checkSegmentBounds(1e-30f, 13);
  checkSegmentBounds(1e30f, 14);
}

// The keys' union alone would not do: a lerped, padded box reaches past it.
TEST(MotionBlurLerp, TheKeysUnionAloneIsNotEnough) {
  const auto [b0, b1] = twoKeyBoxes();
  const Aabb bound = m::segmentBounds(b0, b1), child = m::lerpBox(b0, b1, 0.0f);
  EXPECT_LT(child.lo.x, b0.lo.x);
  EXPECT_LE(bound.lo.x, child.lo.x);
  EXPECT_GE(bound.hi.z, m::lerpBox(b0, b1, 1.0f).hi.z);
}

TEST(MotionBlurLerp, EmptyBoxStaysEmpty) {
  EXPECT_TRUE(m::lerpBox(Aabb{}, Aabb{}, 0.5f).empty());
}

}  // namespace
