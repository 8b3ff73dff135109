#include <gtest/gtest.h>

#include <cstring>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"

namespace {

using anim::GeneratorKind;

class Generators : public ::testing::TestWithParam<GeneratorKind> {};

TEST_P(Generators, SizesFollowTheOptions) {
  anim::GeneratorOptions o;
  o.triangles = 3000;
  o.frames = 12;
  const auto a = anim::generate(GetParam(), o);
  EXPECT_EQ(a.keyframeCount(), 12u);
  EXPECT_GT(a.triangleCount(), 3000u * 2 / 3);
  EXPECT_LT(a.triangleCount(), 3000u * 3 / 2);
  EXPECT_EQ(a.degenerateTriangleCount(), 0u);
  // It moves: the last frame differs from the first.
  EXPECT_NE(a.keyframe(0), a.keyframe(11));
}

TEST_P(Generators, DeterministicForASeedAndDifferentAcrossSeeds) {
  anim::GeneratorOptions o;
  o.triangles = 1000;
  o.frames = 5;
  o.seed = 42;
  const auto a = anim::generate(GetParam(), o);
  const auto b = anim::generate(GetParam(), o);
  EXPECT_EQ(a.allPositions(), b.allPositions());
  o.seed = 43;
  const auto c = anim::generate(GetParam(), o);
  EXPECT_NE(a.allPositions(), c.allPositions());
}

INSTANTIATE_TEST_SUITE_P(All, Generators,
                         ::testing::Values(GeneratorKind::Explode, GeneratorKind::Wave, GeneratorKind::Swap),
                         [](const auto& p) { return std::string(anim::generatorName(p.param)); });

TEST(GeneratorsBehaviour, ExplodeFragmentsSpreadOut) {
  anim::GeneratorOptions o;
  o.triangles = 2000;
  o.frames = 10;
  const auto a = anim::generate(GeneratorKind::Explode, o);
  const auto first = a.keyframeBounds(0), last = a.keyframeBounds(9);
  EXPECT_GT(last.max[0] - last.min[0], 3.0f * (first.max[0] - first.min[0]));
}

TEST(GeneratorsBehaviour, SwapGroupsExchangeSides) {
  anim::GeneratorOptions o;
  o.triangles = 960;  // 20 spheres
  o.frames = 3;
  const auto a = anim::generate(GeneratorKind::Swap, o);
  // The first vertex belongs to group A (moves +x), the last to group B (moves -x).
  const auto f0 = a.keyframe(0), f2 = a.keyframe(2);
  EXPECT_GT(f2[0], f0[0] + 1.0f);
  EXPECT_LT(f2[f2.size() - 3], f0[f0.size() - 3] - 1.0f);
}

TEST(GeneratorsBehaviour, RejectsAbsurdSizesAndUnknownKinds) {
  anim::GeneratorOptions o;
  o.triangles = 0;
  EXPECT_THROW(anim::generate(GeneratorKind::Wave, o), tsah::ConfigError);
  o.triangles = 40'000'000;
  o.frames = 1000;
  EXPECT_THROW(anim::generate(GeneratorKind::Wave, o), tsah::ConfigError);
  EXPECT_THROW(anim::parseGeneratorKind("implode"), tsah::ConfigError);
  EXPECT_EQ(anim::parseGeneratorKind("swap"), GeneratorKind::Swap);
}

}  // namespace
