// CpuRuntime with Config::movingVertices: after one full update, an update reads only the moving
// vertices and refits only the subtrees that hold them (bvh2, bvh4, bvh8). The tree equals a full
// refit's bit for bit; the static coordinates are never read (NaN there changes nothing); a blurred
// frame, a rebuild or a bad coordinate fall back or refuse as documented. A blurred frame's keys
// likewise read only the moving vertices and refit only the moving nodes of a key set refitted
// before.
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <vector>

#include "shutter_checks.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/sah_builder.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace {

template <class T>
bool sameBytes(std::span<const T> a, std::span<const T> b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size_bytes()) == 0;
}

// Every box and triangle the runtime traces: the binary tree and its Woop triangles, or the wide
// tree's nodes and packets, and the root box.
void expectSameTree(const tsah::CpuRuntime& got, const tsah::CpuRuntime& expected) {
  const tsah::Aabb a = got.bounds(), b = expected.bounds();
  ASSERT_EQ(std::memcmp(&a, &b, sizeof a), 0) << "root box";
  if (got.wide4()) {
    ASSERT_TRUE(sameBytes(got.wide4()->nodes(), expected.wide4()->nodes())) << "bvh4 nodes";
    ASSERT_TRUE(sameBytes(got.wide4()->packets(), expected.wide4()->packets())) << "bvh4 packets";
  } else if (got.wide8()) {
    ASSERT_TRUE(sameBytes(got.wide8()->nodes(), expected.wide8()->nodes())) << "bvh8 nodes";
    ASSERT_TRUE(sameBytes(got.wide8()->packets(), expected.wide8()->packets())) << "bvh8 packets";
  } else {
    ASSERT_TRUE(sameBytes(std::span<const tsah::GpuBvhNode>(got.tree().nodes),
                          std::span<const tsah::GpuBvhNode>(expected.tree().nodes)))
        << "bvh2 nodes";
    ASSERT_TRUE(sameBytes(got.woop(), expected.woop())) << "Woop triangles";
  }
}

class MovingRefit : public ::testing::TestWithParam<tsah::Layout> {
 protected:
  void SetUp() override {
    if (!tsah::layoutSupported(GetParam())) GTEST_SKIP() << "no kernels for this layout on this processor";
    ASSERT_GT(animation.movingVertexCount(), 0u);
    ASSERT_LT(animation.movingVertexCount(), animation.vertexCount() / 2);
  }
  tsah::CpuRuntime runtime(bool declareMoving) const {
    tsah::CpuRuntime::Config config(2);
    config.layout = GetParam();
    if (declareMoving)
      config.movingVertices = std::vector<uint32_t>(animation.movingVertices().begin(), animation.movingVertices().end());
    return tsah::CpuRuntime(tree, {animation.indices().begin(), animation.indices().end()}, animation.vertexCount(),
                            config);
  }
  double timeAt(double f) const { return animation.startTime() + f * (animation.endTime() - animation.startTime()); }
  // The animation's positions at t with the static vertices' x set to NaN.
  std::vector<float> poisoned(double t) const {
    std::vector<float> positions = animation.positionsAt(t);
    std::vector<uint8_t> moves(animation.vertexCount(), 0);
    for (uint32_t v : animation.movingVertices()) moves[v] = 1;
    for (uint32_t v = 0; v < animation.vertexCount(); ++v)
      if (!moves[v]) positions[3 * v] = std::numeric_limits<float>::quiet_NaN();
    return positions;
  }
  // The blurred frame of the shutter [open, close] (its keys: tsah::motion::shutterKeys), the
  // static coordinates NaN when `poison`.
  void updateShutter(tsah::CpuRuntime& rt, double open, double close, bool poison) const {
    const std::vector<double> keys = tsah::motion::shutterKeys(animation.times(), open, close);
    std::vector<std::vector<float>> positions;
    for (double t : keys) positions.push_back(poison ? poisoned(t) : animation.positionsAt(t));
    const std::vector<std::span<const float>> spans(positions.begin(), positions.end());
    rt.updateShutter(tsah::motion::keyFractions(keys), spans);
  }

  const anim::Animation animation = tsah::test::mostlyStaticAnimation();
  const tsah::FlatBvh tree =
      tsah::flattenBvh(tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(animation, 0)));
};

TEST_P(MovingRefit, EqualsAFullRefitAndNeverReadsTheStaticVertices) {
  tsah::CpuRuntime moving = runtime(true), full = runtime(false);
  moving.update(animation.positionsAt(timeAt(0.0)));
  EXPECT_FALSE(moving.lastUpdateMovingOnly());  // the first update puts the static part in place
  for (const double f : {0.4, 0.9, 0.15, 1.0}) {
    SCOPED_TRACE("f = " + std::to_string(f));
    std::vector<float> positions = animation.positionsAt(timeAt(f));
    full.update(positions);
    // The static vertices' coordinates are not read: poison them.
    std::vector<uint8_t> moves(animation.vertexCount(), 0);
    for (uint32_t v : animation.movingVertices()) moves[v] = 1;
    for (uint32_t v = 0; v < animation.vertexCount(); ++v)
      if (!moves[v]) positions[3 * v] = std::numeric_limits<float>::quiet_NaN();
    moving.update(positions);
    EXPECT_TRUE(moving.lastUpdateMovingOnly());
    expectSameTree(moving, full);
  }
}

TEST_P(MovingRefit, ABlurredFrameMakesTheNextUpdateFull) {
  tsah::CpuRuntime moving = runtime(true), full = runtime(false);
  moving.update(animation.positionsAt(timeAt(0.0)));
  const std::vector<float> k0 = animation.positionsAt(timeAt(0.2)), k1 = animation.positionsAt(timeAt(0.3));
  const std::vector<std::span<const float>> keys{k0, k1};
  const std::vector<float> times{0.0f, 1.0f};
  moving.updateShutter(times, keys);
  moving.update(animation.positionsAt(timeAt(0.6)));
  EXPECT_FALSE(moving.lastUpdateMovingOnly());
  full.update(animation.positionsAt(timeAt(0.6)));
  expectSameTree(moving, full);
  moving.update(animation.positionsAt(timeAt(0.7)));
  EXPECT_TRUE(moving.lastUpdateMovingOnly());
  full.update(animation.positionsAt(timeAt(0.7)));
  expectSameTree(moving, full);
}

// Shutters of two and three keys in turn: after one full refit of each key set, a key reads only
// the moving vertices (the static ones NaN) and refits only the moving nodes; every key set equals
// a full refit's bit for bit (a key set refitted from another key's static part, or a moving node
// skipped, would differ). A key set new to the frame (the third key) is refitted in full once.
TEST_P(MovingRefit, BlurredKeysRefitOnlyWhatMovesAndEqualAFullRefit) {
  const bool wide = GetParam() != tsah::Layout::Bvh2;
  tsah::CpuRuntime moving = runtime(true), full = runtime(false);
  const std::span<const double> t = animation.times();
  ASSERT_GE(t.size(), 4u);
  const double a = 0.5 * (t[0] + t[1]), b = 0.5 * (t[1] + t[2]), c = 0.5 * (t[2] + t[3]);
  struct Frame {
    double open, close;
    uint32_t keys, movingOnly;  // keys refitted, of them refitted moving-only
  };
  const std::vector<Frame> frames{
      {t[0], a, 2, wide ? 0u : 1u},  // the first reads in full (bvh2: its tree then holds a refit)
      {b, c, 3, wide ? 2u : 3u},     // two key sets from the frame before, one new
      {a, 0.5 * (a + t[1]), 2, 2},
      {a, 0.5 * (a + t[1]), 0, 0},   // the same keys again: compared on the moving vertices, reused
      {a, b, 2, wide ? 1u : 2u}};   // a reused (its set moved on), t[1] and b refitted: one set spare, one new
  for (std::size_t f = 0; f < frames.size(); ++f) {
    SCOPED_TRACE("frame " + std::to_string(f));
    updateShutter(moving, frames[f].open, frames[f].close, f > 0);
    updateShutter(full, frames[f].open, frames[f].close, false);
    EXPECT_EQ(moving.keysRefitted(), frames[f].keys);
    EXPECT_EQ(moving.keysRefittedMovingOnly(), frames[f].movingOnly);
    EXPECT_EQ(full.keysRefittedMovingOnly(), 0u);
    tsah::test::expectSameShutter(moving, full);
  }
  // After an instant update the next frame's key sets are new: refitted in full, from the static
  // positions that update read.
  moving.update(animation.positionsAt(timeAt(0.5)));
  full.update(animation.positionsAt(timeAt(0.5)));
  updateShutter(moving, b, c, true);
  updateShutter(full, b, c, false);
  EXPECT_EQ(moving.keysRefittedMovingOnly(), wide ? 0u : 3u);
  tsah::test::expectSameShutter(moving, full);
  // A bad moving coordinate at a key is refused and changes nothing.
  std::vector<float> bad = poisoned(a), good = animation.positionsAt(b);
  const uint32_t v = animation.movingVertices()[animation.movingVertexCount() / 3];
  bad[3 * v + 2] = std::numeric_limits<float>::infinity();
  const std::vector<std::span<const float>> keys{good, bad};
  const std::vector<float> times{0.0f, 1.0f};
  try {
    moving.updateShutter(times, keys);
    FAIL() << "an infinite moving coordinate was taken";
  } catch (const tsah::DataError& e) {
    EXPECT_NE(std::string(e.what()).find("vertex " + std::to_string(v)), std::string::npos) << e.what();
  }
  tsah::test::expectSameShutter(moving, full);
}

TEST_P(MovingRefit, ABadMovingCoordinateIsRefusedAndChangesNothing) {
  tsah::CpuRuntime moving = runtime(true), reference = runtime(false);
  moving.update(animation.positionsAt(timeAt(0.0)));
  moving.update(animation.positionsAt(timeAt(0.5)));
  reference.update(animation.positionsAt(timeAt(0.5)));
  std::vector<float> bad = animation.positionsAt(timeAt(0.8));
  const uint32_t v = animation.movingVertices()[animation.movingVertexCount() / 2];
  bad[3 * v + 1] = std::numeric_limits<float>::infinity();
  try {
    moving.update(bad);
    FAIL() << "an infinite moving coordinate was taken";
  } catch (const tsah::DataError& e) {
    EXPECT_NE(std::string(e.what()).find("vertex " + std::to_string(v)), std::string::npos) << e.what();
  }
  expectSameTree(moving, reference);
  EXPECT_THROW(moving.update(std::vector<float>(3)), tsah::DataError);  // the count
}

INSTANTIATE_TEST_SUITE_P(Layouts, MovingRefit,
                         ::testing::Values(tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8),
                         [](const ::testing::TestParamInfo<tsah::Layout>& p) { return std::string(tsah::name(p.param)); });

TEST(MovingRefitConfig, MovingVerticesMustBeAscendingAndInRange) {
  const anim::Animation a = tsah::test::mostlyStaticAnimation(40, 10);
  const tsah::FlatBvh tree = tsah::flattenBvh(tsah::SweepSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  for (const std::vector<uint32_t>& ids : {std::vector<uint32_t>{3, 2}, std::vector<uint32_t>{1, 1},
                                           std::vector<uint32_t>{a.vertexCount()}}) {
    tsah::CpuRuntime::Config config(1);
    config.movingVertices = ids;
    EXPECT_THROW(tsah::CpuRuntime(tree, {a.indices().begin(), a.indices().end()}, a.vertexCount(), config),
                 tsah::ConfigError);
  }
}

}  // namespace
