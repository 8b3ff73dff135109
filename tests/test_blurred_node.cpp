// tsah/layout/blurred_node.hpp: the GPU blurred layout's node record. binary16 rounding in each
// direction against every binary16 value; the moved box side (key s plus f times its rounded
// change, one fused multiply-add) never inside the exact lerp of the two keys, close to key s + 1
// at f = 1; and the whole chain (pre-pad, record, move) containing every vertex lerped between
// vertices inside the unpadded key boxes, under round-to-nearest and under any rounding.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "tsah/core/directed_rounding.hpp"
#include "tsah/layout/blurred_node.hpp"
#include "tsah/layout/motion_blur.hpp"

namespace {

namespace m = tsah::motion;
using tsah::Aabb;
using tsah::GpuBvhNode;
using tsah::Vec3;

// Every finite binary16 value, increasing.
std::vector<double> finiteHalves() {
  std::vector<double> v;
  for (uint32_t h = 0; h < 0x10000u; ++h)
    if (((h >> 10) & 0x1fu) != 31) v.push_back(m::halfValue(uint16_t(h)));
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());  // +0 and -0
  return v;
}

TEST(BlurredNode, HalfRoundingIsDirectedAndTight) {
  const std::vector<double> halves = finiteHalves();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  std::uniform_int_distribution<int> exponent(-30, 17);
  std::vector<float> xs = {0.0f, -0.0f, 65504.0f, -65504.0f, 1.0f, 1.0f + 0x1p-11f, 1.0f + 0x1p-23f, -1.0f - 0x1p-23f,
                           0x1p-24f, 0x1p-25f, -0x1p-25f, 0x1p-14f, 0x1p-14f - 0x1p-30f, 3.0e-8f, 6.1e-5f, 1e5f, -1e5f};
  for (int i = 0; i < 200000; ++i) xs.push_back(std::ldexp(unit(rng), exponent(rng)));
  for (const float x : xs) {
    const double down = m::halfValue(m::halfDirected(x, true)), up = m::halfValue(m::halfDirected(x, false));
    // The exact answers: the largest value <= x and the smallest >= x (infinite past 65504).
    const auto above = std::lower_bound(halves.begin(), halves.end(), double(x));
    const double ceil = above == halves.end() ? INFINITY : *above;
    const auto below = std::upper_bound(halves.begin(), halves.end(), double(x));
    const double floor = below == halves.begin() ? -INFINITY : *(below - 1);
    ASSERT_EQ(down, floor) << "x = " << x;
    ASSERT_EQ(up, ceil) << "x = " << x;
  }
}

// A node whose two children both hold box b (the record's rows then test both children alike).
GpuBvhNode nodeOf(const Aabb& b) {
  GpuBvhNode n{};
  n.setChildBox(0, b);
  n.setChildBox(1, b);
  return n;
}

// Child c's box at f from a record, as the GPU traversal moves it (bvh2_traversal.cuh).
Aabb movedBox(const m::BlurredNodeSegment& r, float f) {
  const float fs = f * r.scale;
  const float* a = &r.node.c0loX;
  float v[12];
  for (int i = 0; i < 12; ++i) v[i] = std::fma(fs, m::halfValue(r.delta[i]), a[i]);
  GpuBvhNode moved = r.node;
  std::copy(v, v + 12, &moved.c0loX);
  return moved.childBox(0);
}

Aabb randomBox(std::mt19937& rng, float magnitude) {
  std::uniform_real_distribution<float> coord(-magnitude, magnitude);
  Aabb b;
  b.extend(Vec3{coord(rng), coord(rng), coord(rng)});
  b.extend(Vec3{coord(rng), coord(rng), coord(rng)});
  return b;
}

// Moved sides never lie inside the exact lerp of the two keys' sides (beyond the fused
// multiply-add's one rounding, which the pre-pad covers); at f = 0 they are key s's; at f = 1 the
// outward rounding costs at most a binary16 unit of the largest change.
void checkMovedSides(float magnitude, float motion, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f), shift(-motion, motion);
  for (int trial = 0; trial < 20000; ++trial) {
    const Aabb a = randomBox(rng, magnitude);
    Aabb b = a;
    for (int axis = 0; axis < 3; ++axis) {
      b.lo[axis] += shift(rng);
      b.hi[axis] = std::max(b.lo[axis], b.hi[axis] + shift(rng));
    }
    const m::BlurredNodeSegment r = m::encodeNodeSegment(nodeOf(a), nodeOf(b), false);
    double largest = 0.0;
    for (int axis = 0; axis < 3; ++axis)
      largest = std::max({largest, std::fabs(double(b.lo[axis]) - a.lo[axis]), std::fabs(double(b.hi[axis]) - a.hi[axis])});
    const Aabb at0 = movedBox(r, 0.0f), at1 = movedBox(r, 1.0f);
    for (float f : {unit(rng), unit(rng) * 1e-6f, 1.0f - unit(rng) * 1e-6f}) {
      const Aabb moved = movedBox(r, f);
      for (int axis = 0; axis < 3; ++axis) {
        const double lo = a.lo[axis] + double(f) * (double(b.lo[axis]) - a.lo[axis]);
        const double hi = a.hi[axis] + double(f) * (double(b.hi[axis]) - a.hi[axis]);
        const double slack = 0x1p-24 * std::max(std::fabs(lo), std::fabs(hi));  // the fma's rounding
        ASSERT_LE(moved.lo[axis], lo + slack) << "axis " << axis << " f " << f;
        ASSERT_GE(moved.hi[axis], hi - slack) << "axis " << axis << " f " << f;
      }
    }
    for (int axis = 0; axis < 3; ++axis) {
      ASSERT_EQ(at0.lo[axis], a.lo[axis]);
      ASSERT_EQ(at0.hi[axis], a.hi[axis]);
      ASSERT_LE(at1.lo[axis], b.lo[axis]);
      ASSERT_GE(at1.hi[axis], b.hi[axis]);
      const double unitOfChange = largest * 0x1p-10 + 0x1p-24 * r.scale;
      ASSERT_LE(double(b.lo[axis]) - at1.lo[axis], unitOfChange + 0x1p-23 * std::fabs(b.lo[axis])) << "axis " << axis;
      ASSERT_LE(double(at1.hi[axis]) - b.hi[axis], unitOfChange + 0x1p-23 * std::fabs(b.hi[axis])) << "axis " << axis;
    }
  }
}

TEST(BlurredNode, MovedSidesStayOutsideTheKeysLerp) {
  checkMovedSides(1.0f, 0.01f, 1);
  checkMovedSides(1.0f, 1.0f, 2);
  checkMovedSides(1e4f, 3.0f, 3);
  checkMovedSides(1e6f, 1e5f, 4);   // changes past binary16's range: a scale above 1
  checkMovedSides(1e-3f, 1e-7f, 5);  // changes in binary16's subnormal range: a scale below 1
  checkMovedSides(100.0f, 0.0f, 6);  // no change: the record moves nothing
}

// The whole chain, as the layout builds and the GPU reads it: key boxes around random vertices,
// pre-padded over both keys, recorded, moved to f; the box holds the vertex lerped with f in
// round-to-nearest (the triangle test's own) and under every directed rounding.
TEST(BlurredNode, MovedBoxContainsLerpedVerticesUnderRounding) {
  namespace r = tsah::rounding;
  for (const float magnitude : {1.0f, 1e4f, 1e-30f, 1e30f}) {
    std::mt19937 rng(uint32_t(std::log10(magnitude) + 40));
    std::uniform_real_distribution<float> coord(-magnitude, magnitude), unit(0.0f, 1.0f);
    for (int trial = 0; trial < 20000; ++trial) {
      const Vec3 v0{coord(rng), coord(rng), coord(rng)}, v1{coord(rng), coord(rng), coord(rng)};
      Aabb b0, b1;
      b0.extend(v0);
      b1.extend(v1);
      const Vec3 mag = m::foldMagnitudes(b1, m::foldMagnitudes(b0, Vec3{0.0f, 0.0f, 0.0f}));
      const m::BlurredNodeSegment record =
          m::encodeNodeSegment(nodeOf(m::prepadBox(b0, mag)), nodeOf(m::prepadBox(b1, mag)), false);
      float f = unit(rng);
      if (trial % 4 == 1) f = 1.0f - f * 1e-6f;
      if (trial % 4 == 2) f = f * 1e-6f;
      const Aabb box = movedBox(record, f);
      const Vec3 v = m::lerpVertex(v0, v1, f);
      for (int a = 0; a < 3; ++a) {
        ASSERT_LE(box.lo[a], v[a]) << "axis " << a << " f " << f << " magnitude " << magnitude;
        ASSERT_GE(box.hi[a], v[a]) << "axis " << a << " f " << f << " magnitude " << magnitude;
        // The vertex's lerp under any rounding of each step (test_motion_blur.cpp's bounds).
        const float gl = r::subDown(1.0f, f), gh = r::subUp(1.0f, f);
        const float lower = r::addDown(std::fmin(r::mulDown(gl, v0[a]), r::mulDown(gh, v0[a])), r::mulDown(f, v1[a]));
        const float upper = r::addUp(std::fmax(r::mulUp(gl, v0[a]), r::mulUp(gh, v0[a])), r::mulUp(f, v1[a]));
        ASSERT_LE(box.lo[a], lower);
        ASSERT_GE(box.hi[a], upper);
      }
    }
  }
}

// A record of boxes that are the same at every key carries the alike bit and zero changes.
TEST(BlurredNode, AlikeRecordsMoveNothing) {
  std::mt19937 rng(9);
  const Aabb a = randomBox(rng, 50.0f);
  const m::BlurredNodeSegment r = m::encodeNodeSegment(nodeOf(a), nodeOf(a), true);
  EXPECT_TRUE(r.node.count0 & m::kKeysAlikeBit);
  for (uint16_t d : r.delta) EXPECT_EQ(m::halfValue(d), 0.0);
  const Aabb moved = movedBox(r, 0.73f);
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_EQ(moved.lo[axis], a.lo[axis]);
    EXPECT_EQ(moved.hi[axis], a.hi[axis]);
  }
}

}  // namespace
