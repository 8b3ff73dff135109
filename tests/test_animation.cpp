#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "anim/animation.hpp"
#include "tsah/base/error.hpp"

namespace {

// Two triangles sharing an edge, three keyframes at t = 0, 1, 3.
anim::Animation makeQuad() {
  std::vector<uint32_t> idx{0, 1, 2, 0, 2, 3};
  std::vector<float> pos;
  const float base[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  for (float dx : {0.0f, 2.0f, 6.0f})
    for (int v = 0; v < 4; ++v) {
      pos.push_back(base[3 * v] + dx);
      pos.push_back(base[3 * v + 1]);
      pos.push_back(base[3 * v + 2] + (v == 2 ? dx : 0.0f));
    }
  return anim::Animation(idx, 4, pos, {0.0, 1.0, 3.0}, "quad");
}

TEST(Animation, CountsAndKeyframes) {
  const auto a = makeQuad();
  EXPECT_EQ(a.triangleCount(), 2u);
  EXPECT_EQ(a.vertexCount(), 4u);
  EXPECT_EQ(a.keyframeCount(), 3u);
  EXPECT_EQ(a.keyframe(1)[0], 2.0f);
  EXPECT_DOUBLE_EQ(a.startTime(), 0.0);
  EXPECT_DOUBLE_EQ(a.endTime(), 3.0);
  EXPECT_EQ(a.degenerateTriangleCount(), 0u);
}

TEST(Animation, InterpolatesBetweenNeighbouringKeyframes) {
  const auto a = makeQuad();
  // t = 2 lies halfway between keyframes at 1 (dx = 2) and 3 (dx = 6): dx = 4.
  const auto p = a.positionsAt(2.0);
  EXPECT_FLOAT_EQ(p[0], 4.0f);
  EXPECT_FLOAT_EQ(p[3], 5.0f);
  EXPECT_FLOAT_EQ(p[8], 4.0f);  // vertex 2 z = dx
  // t = 0.25: a quarter of the way from dx = 0 to dx = 2.
  EXPECT_FLOAT_EQ(a.positionsAt(0.25)[0], 0.5f);
  // Clamped outside the range.
  EXPECT_FLOAT_EQ(a.positionsAt(-5.0)[0], 0.0f);
  EXPECT_FLOAT_EQ(a.positionsAt(10.0)[0], 6.0f);
}

TEST(Animation, BoundsPerFrameAndOverall) {
  const auto a = makeQuad();
  const auto b0 = a.keyframeBounds(0);
  EXPECT_EQ(b0.min[0], 0.0f);
  EXPECT_EQ(b0.max[0], 1.0f);
  const auto b = a.bounds();
  EXPECT_EQ(b.max[0], 7.0f);
  EXPECT_EQ(b.max[2], 6.0f);
  const auto bt = a.boundsAt(2.0);
  EXPECT_FLOAT_EQ(bt.min[0], 4.0f);
  EXPECT_FLOAT_EQ(bt.max[0], 5.0f);
}

TEST(Animation, UniformResampling) {
  const auto a = makeQuad();
  const auto r = a.resample(5);
  ASSERT_EQ(r.keyframeCount(), 5u);
  const double expected[5] = {0.0, 0.75, 1.5, 2.25, 3.0};
  for (uint32_t i = 0; i < 5; ++i) {
    EXPECT_DOUBLE_EQ(r.times()[i], expected[i]);
    EXPECT_FLOAT_EQ(r.keyframe(i)[0], a.positionsAt(expected[i])[0]);
  }
  EXPECT_EQ(a.resample(50).keyframeCount(), 50u);
  EXPECT_EQ(a.uniformTimes(1).size(), 1u);
  EXPECT_THROW(a.resample(0), tsah::Error);
  // 4e9 frames x 4 vertices would need ~190 GB: refused up front with a clear error, not OOM-killed.
  EXPECT_THROW(a.resample(4'000'000'000u), tsah::Error);
}

TEST(Animation, SegmentKeepsInteriorKeyframes) {
  const auto a = makeQuad();
  const auto s = a.segment(0.5, 2.0);
  ASSERT_EQ(s.keyframeCount(), 3u);  // 0.5, 1, 2
  EXPECT_DOUBLE_EQ(s.times()[1], 1.0);
  EXPECT_FLOAT_EQ(s.keyframe(0)[0], 1.0f);
  EXPECT_FLOAT_EQ(s.keyframe(2)[0], 4.0f);
}

TEST(Animation, RejectsNanAndBadIndices) {
  std::vector<float> pos(9, 0.0f);
  pos[4] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(anim::Animation({0, 1, 2}, 3, pos, {0.0}), tsah::FileError);
  EXPECT_THROW(anim::Animation({0, 1, 3}, 3, std::vector<float>(9, 0.0f), {0.0}), tsah::FileError);
  EXPECT_THROW(anim::Animation({0, 1, 2}, 3, std::vector<float>(18, 0.0f), {1.0, 0.5}),
               tsah::FileError);
  EXPECT_THROW(anim::Animation({0, 1, 2}, 3, std::vector<float>(8, 0.0f), {0.0}), tsah::FileError);
}

TEST(Animation, CountsDegenerateTriangles) {
  const std::vector<float> pos{0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0};
  const anim::Animation a({0, 1, 2, 0, 1, 3}, 4, pos, {0.0});
  EXPECT_EQ(a.degenerateTriangleCount(), 1u);
  EXPECT_EQ(a.triangleCount(), 2u);
}

// Found while writing fuzz_scene: a scene's memory statement multiplies hostile counts; the size saturates
// instead of wrapping around to a small number that would pass the check.
TEST(Animation, MemoryBytesForSaturatesInsteadOfWrapping) {
  const uint64_t big = uint64_t(1) << 32;
  EXPECT_EQ(anim::Animation::memoryBytesFor(0, big, big, big), std::numeric_limits<std::size_t>::max());
  EXPECT_EQ(anim::Animation::memoryBytesFor(1, 3, 3, 2), 12u + 2 * 3 * 12 + 2 * 8);
}

}  // namespace
