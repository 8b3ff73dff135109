// The CPU batch of rays given as arrays (tsah::RayArrays): the same hits as the batch of Ray structs
// in every layout, misses as inf, ray counts that do not fill the last chunk, one tmin / tmax for all
// rays, and the errors (sizes, the first bad ray).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "anim/generators.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

struct Batch {
  std::vector<float> origins, directions, tmin, tmax;
  std::size_t size() const { return tmin.size(); }
  tsah::RayArrays arrays() const { return {origins, directions, tmin, tmax}; }
  std::vector<tsah::Ray> rays() const {
    std::vector<tsah::Ray> out;
    for (std::size_t i = 0; i < size(); ++i)
      out.push_back({{origins[3 * i], origins[3 * i + 1], origins[3 * i + 2]}, tmin[i],
                     {directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]}, tmax[i]});
    return out;
  }
};

class RayArrays : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    animation_ = std::make_unique<anim::Animation>(
        tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 3000, 6, 3));
    tree_ = std::make_unique<tsah::FlatBvh>(
        tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(*animation_, 0))));
  }
  static void TearDownTestSuite() {
    animation_.reset();
    tree_.reset();
  }

  // A runtime of this layout on `threads` threads at the animation's middle, or null when this
  // processor runs no kernels of the layout.
  static std::unique_ptr<tsah::CpuRuntime> runtime(tsah::Layout layout, uint32_t threads = 2) {
    if (!tsah::layoutSupported(layout)) return nullptr;
    tsah::CpuRuntime::Config config(threads);
    config.layout = layout;
    auto rt = std::make_unique<tsah::CpuRuntime>(
        *tree_, std::vector<uint32_t>(animation_->indices().begin(), animation_->indices().end()),
        animation_->vertexCount(), config);
    rt->update(animation_->positionsAt(time()));
    return rt;
  }

  static double time() { return animation_->uniformTimes(3)[1]; }

  // Rays from around the scene's box towards random triangles' centres (most hit; the exploding
  // scene is mostly empty space), every third one short and every fifth one starting past zero:
  // per-ray limits that differ between neighbours.
  static Batch batch(std::size_t count) {
    const tsah::Aabb box = tsah::test::boxOf(animation_->bounds());
    const tsah::Vec3 size = box.extent();
    const std::vector<float> p = animation_->positionsAt(time());
    const auto vertex = [&](uint32_t v) { return tsah::Vec3{p[3 * v], p[3 * v + 1], p[3 * v + 2]}; };
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    Batch b;
    for (std::size_t i = 0; i < count; ++i) {
      const uint32_t* tri = animation_->indices().data() + 3 * (rng() % animation_->triangleCount());
      const tsah::Vec3 target = (vertex(tri[0]) + vertex(tri[1]) + vertex(tri[2])) * (1.0f / 3.0f);
      const tsah::Vec3 org = box.center() + tsah::Vec3{(u(rng) - 0.5f) * size.x, (u(rng) - 0.5f) * size.y,
                                                       (u(rng) - 0.5f) * size.z} * 3.0f;
      const tsah::Vec3 dir = target - org;
      b.origins.insert(b.origins.end(), {org.x, org.y, org.z});
      b.directions.insert(b.directions.end(), {dir.x, dir.y, dir.z});
      b.tmin.push_back(i % 5 == 0 ? 0.25f : 0.0f);
      b.tmax.push_back(i % 3 == 0 ? 0.9f : kInf);
    }
    return b;
  }

  static std::unique_ptr<anim::Animation> animation_;
  static std::unique_ptr<tsah::FlatBvh> tree_;
};

std::unique_ptr<anim::Animation> RayArrays::animation_;
std::unique_ptr<tsah::FlatBvh> RayArrays::tree_;

void expectSameHit(const tsah::Hit& got, const tsah::Hit& want, const std::string& what) {
  if (!want.valid()) {
    EXPECT_EQ(got.tri, tsah::kNoHit) << what;
    EXPECT_EQ(got.t, kInf) << what;
    EXPECT_EQ(got.u, 0.0f) << what;
    EXPECT_EQ(got.v, 0.0f) << what;
    return;
  }
  EXPECT_EQ(0, std::memcmp(&got, &want, sizeof got)) << what << ": t " << got.t << " vs " << want.t;
}

// 3 * 1024 + 5 rays: the last of the batch's chunks (1024 rays) is short, and a chunk of a thread
// count that does not divide the rays starts inside one; each layout and thread count.
TEST_F(RayArrays, SameHitsAsTheRayStructBatchInEveryLayout) {
  const Batch b = batch(3 * 1024 + 5);
  const std::vector<tsah::Ray> rays = b.rays();
  for (const tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
    for (const uint32_t threads : {1u, 3u}) {
      const auto rt = runtime(layout, threads);
      if (!rt) continue;
      const std::string what = std::string(tsah::name(layout)) + ", " + std::to_string(threads) + " threads";
      const std::vector<tsah::Hit> want = tsah::closestHits(*rt, rays);
      const std::vector<uint8_t> wantAny = tsah::anyHits(*rt, rays);
      std::vector<tsah::Hit> got(b.size(), tsah::Hit{-1.0f, -1.0f, -1.0f, 12345u});
      std::vector<uint8_t> any(b.size(), 7);
      tsah::closestHits(*rt, b.arrays(), got);
      tsah::anyHits(*rt, b.arrays(), any);
      std::size_t hits = 0;
      for (std::size_t i = 0; i < b.size(); ++i) {
        expectSameHit(got[i], want[i], what + " ray " + std::to_string(i));
        EXPECT_EQ(any[i], wantAny[i]) << what << " ray " << i;
        hits += want[i].valid() ? 1 : 0;
      }
      EXPECT_GT(hits, b.size() / 5) << what;  // a meaningful batch: hits and misses
      EXPECT_LT(hits, b.size()) << what;
    }
  }
}

TEST_F(RayArrays, OneLimitHoldsForEveryRay) {
  Batch b = batch(1500);
  std::fill(b.tmin.begin(), b.tmin.end(), 0.1f);
  std::fill(b.tmax.begin(), b.tmax.end(), 0.8f);
  const auto rt = runtime(tsah::Layout::Bvh2);
  const std::vector<tsah::Hit> want = tsah::closestHits(*rt, b.rays());
  const float lo = 0.1f, hi = 0.8f;
  tsah::RayArrays arrays = b.arrays();
  arrays.tmin = {&lo, 1};
  arrays.tmax = {&hi, 1};
  std::vector<tsah::Hit> got(b.size());
  tsah::closestHits(*rt, arrays, got);
  for (std::size_t i = 0; i < b.size(); ++i) expectSameHit(got[i], want[i], "ray " + std::to_string(i));
}

TEST_F(RayArrays, EmptyBatch) {
  const auto rt = runtime(tsah::Layout::Bvh2);
  const float zero = 0.0f;
  EXPECT_NO_THROW(tsah::closestHits(*rt, tsah::RayArrays{{}, {}, {&zero, 1}, {&zero, 1}}, std::span<tsah::Hit>()));
  EXPECT_NO_THROW(tsah::anyHits(*rt, tsah::RayArrays{}, std::span<uint8_t>()));
}

void expectRefused(const std::function<void()>& call, const std::string& message) {
  try {
    call();
    ADD_FAILURE() << "not refused: " << message;
  } catch (const tsah::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()), message);
  }
}

TEST_F(RayArrays, SizesThatDisagreeAreRefused) {
  const auto rt = runtime(tsah::Layout::Bvh2);
  const Batch b = batch(10);
  std::vector<tsah::Hit> hits(10);
  tsah::RayArrays arrays = b.arrays();
  arrays.origins = arrays.origins.first(29);
  expectRefused([&] { tsah::closestHits(*rt, arrays, hits); }, "rays: 29 origin coordinates (3 per ray)");
  arrays = b.arrays();
  arrays.directions = arrays.directions.first(27);
  expectRefused([&] { tsah::closestHits(*rt, arrays, hits); }, "rays: 27 direction coordinates for 10 rays");
  arrays = b.arrays();
  arrays.tmax = arrays.tmax.first(9);
  expectRefused([&] { tsah::closestHits(*rt, arrays, hits); }, "rays: 9 tmax values for 10 rays (1 or one per ray)");
  arrays = b.arrays();
  arrays.tmin = {};
  expectRefused([&] { tsah::closestHits(*rt, arrays, hits); }, "rays: 0 tmin values for 10 rays (1 or one per ray)");
  expectRefused([&] { tsah::closestHits(*rt, b.arrays(), std::span(hits).first(9)); }, "rays: 9 hits for 10 rays");
  std::vector<uint8_t> flags(11);
  expectRefused([&] { tsah::anyHits(*rt, b.arrays(), flags); }, "rays: 11 occlusion flags for 10 rays");
}

// Bad rays in two chunks far apart, the later one in the chunk a thread may trace first: the
// message names the first, as checkRays does for a batch of Ray structs.
TEST_F(RayArrays, TheFirstBadRayIsNamed) {
  const auto rt = runtime(tsah::Layout::Bvh2, 2);
  Batch b = batch(5000);
  b.directions[3 * 4990 + 1] = std::numeric_limits<float>::quiet_NaN();
  b.tmax[1030] = std::numeric_limits<float>::quiet_NaN();
  std::vector<tsah::Hit> hits(b.size());
  std::vector<uint8_t> flags(b.size());
  expectRefused([&] { tsah::closestHits(*rt, b.arrays(), hits); }, "rays: ray 1030: tmax is NaN");
  expectRefused([&] { tsah::anyHits(*rt, b.arrays(), flags); }, "rays: ray 1030: tmax is NaN");
  expectRefused([&] { tsah::checkRays(b.rays()); }, "rays: ray 1030: tmax is NaN");
  b.tmax[1030] = kInf;
  b.tmin[4999] = -1.0f;
  expectRefused([&] { tsah::closestHits(*rt, b.arrays(), hits); }, "rays: ray 4990: direction is not finite");
}

}  // namespace
