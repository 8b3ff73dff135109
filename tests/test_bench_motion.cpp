// The bench's Embree motion-blur peer (bench/embree_motion.hpp): the mapping of times onto Embree's
// evenly spaced time steps, and, when Embree is built, that a ray at a time finds what the toolkit
// finds in the animation's frame at that time; the bench's motion-blur part (bench/motion_bench.hpp)
// on a small scene.
#include <gtest/gtest.h>

#include <vector>

#include "anim/generators.hpp"
#include "bench/embree_motion.hpp"
#include "bench/embree_peer.hpp"
#include "bench/motion_bench.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "bench_setup.hpp"
#include "test_support.hpp"

TEST(EmbreeStepTime, MapsUnevenKeysPieceByPiece) {
  // Keys at times 0, 1, 3 and 4: fractions 0, 1/4, 3/4, 1; Embree's steps at 0, 1/3, 2/3, 1.
  const std::vector<float> keys = tsah::motion::keyFractions(std::vector<double>{0.0, 1.0, 3.0, 4.0});
  const auto at = [&](double time) { return tsah::bench::embreeStepTime(keys, float(time / 4.0)); };
  EXPECT_FLOAT_EQ(at(0.0), 0.0f);
  EXPECT_FLOAT_EQ(at(0.5), 1.0f / 6.0f);
  EXPECT_FLOAT_EQ(at(1.0), 1.0f / 3.0f);
  EXPECT_FLOAT_EQ(at(2.0), 0.5f);  // the middle of the long segment
  EXPECT_FLOAT_EQ(at(3.5), 5.0f / 6.0f);
  EXPECT_FLOAT_EQ(at(4.0), 1.0f);
  EXPECT_FLOAT_EQ(at(9.0), 1.0f);
  EXPECT_FLOAT_EQ(at(-1.0), 0.0f);
  EXPECT_FLOAT_EQ(tsah::bench::embreeStepTime(std::vector<float>{0.0f}, 0.5f), 0.0f);
}

#if TSAH_HAVE_EMBREE
namespace {

struct Moving {
  explicit Moving(anim::GeneratorKind kind, uint32_t keyframes = 6)
      : a(tsah::test::generatedAnimation(kind, 1500, keyframes, 5)) {}
  anim::Animation a;
  tsah::CpuRuntime rt{tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0))),
                      {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2}};

  // The fraction of camera rays (framed on the animation at `time`) for which Embree at
  // `embreeTime` and the toolkit refitted to the animation at `time` hit the same triangle.
  // wholeAnimation: the camera framed on every frame's bounds instead of this time's.
  double agreement(const tsah::bench::EmbreeMotionPeer& peer, double time, float embreeTime, uint32_t* hits,
                   bool wholeAnimation = false) {
    rt.update(a.positionsAt(time));
    const tsah::Aabb now = tsah::test::boxOf(wholeAnimation ? a.bounds() : a.boundsAt(time));
    const tsah::CameraRays cam = tsah::cameraRays(tsah::fitCamera(now, {0, 1, 0}, 45.0f, 1.0f), 64, 64);
    uint32_t same = 0;
    *hits = 0;
    for (uint32_t y = 0; y < 64; ++y)
      for (uint32_t x = 0; x < 64; ++x) {
        const tsah::Ray ray = cam.ray(float(x) + 0.5f, float(y) + 0.5f);
        const tsah::Hit own = rt.closestHit(ray);
        const uint32_t other = peer.closestTriangle(ray, embreeTime);
        same += (own.valid() ? own.tri : tsah::bench::EmbreeMotionPeer::kMiss) == other ? 1u : 0u;
        *hits += own.valid() ? 1u : 0u;
      }
    return double(same) / (64.0 * 64.0);
  }
};

}  // namespace

TEST(EmbreeMotionPeer, TheWholeAnimationAtAnyTimeIsTheFrameAtThatTime) {
  Moving m(anim::GeneratorKind::Wave);
  tsah::bench::EmbreeMotionPeer peer(m.a.indices(), m.a.vertexCount(), 2);
  EXPECT_GE(peer.build(m.a, m.a.times()), 0.0);
  EXPECT_EQ(peer.timeSteps(), m.a.keyframeCount());
  const std::span<const double> times = m.a.times();
  const std::vector<float> keys = tsah::motion::keyFractions(times);
  for (double f : {0.0, 0.37, 0.5, 0.81, 1.0}) {
    const double time = times.front() + f * (times.back() - times.front());
    uint32_t hits = 0;
    EXPECT_GE(m.agreement(peer, time, tsah::bench::embreeStepTime(keys, float(f)), &hits), 0.999) << "time " << time;
    EXPECT_GT(hits, 100u);
  }
}

TEST(EmbreeMotionPeer, MoreKeyframesThanEmbreeTakesPerGeometryStillFollowTheAnimation) {
  // 300 keyframes of two groups passing through each other: Embree holds at most 129 time steps
  // per geometry, so the peer spreads them over three BVHs, each over its part of the time. The
  // camera sees the whole path, where the objects of another part's time, were they traced, would
  // stand.
  Moving m(anim::GeneratorKind::Swap, 300);
  tsah::bench::EmbreeMotionPeer peer(m.a.indices(), m.a.vertexCount(), 2);
  EXPECT_GE(peer.build(m.a, m.a.times()), 0.0);
  EXPECT_EQ(peer.timeSteps(), 300u);
  EXPECT_EQ(peer.pieces(), 3u);
  const std::span<const double> times = m.a.times();
  const std::vector<float> keys = tsah::motion::keyFractions(times);
  // Inside each geometry, at the boundaries between them (keyframes 128 and 256) and at the ends.
  for (double k : {0.0, 30.3, 60.3, 127.9, 128.0, 128.2, 200.5, 256.0, 280.7, 299.0}) {
    const double f = k / 299.0;
    const double time = times.front() + f * (times.back() - times.front());
    uint32_t hits = 0;
    EXPECT_GE(m.agreement(peer, time, tsah::bench::embreeStepTime(keys, float(f)), &hits, true), 0.999)
        << "keyframe " << k;
    EXPECT_GT(hits, 30u);
  }
}

TEST(EmbreeMotionPeer, UnevenKeysInsideAShutterFollowTheAnimation) {
  // Keys at 0, 0.1 and 1 of one keyframe segment (the motion is linear there): a time between
  // them must be mapped piece by piece; evenly spaced steps would put the fragments elsewhere.
  Moving m(anim::GeneratorKind::Explode);
  tsah::bench::EmbreeMotionPeer peer(m.a.indices(), m.a.vertexCount(), 2);
  const double open = m.a.times()[2], close = m.a.times()[3];
  const std::vector<double> times{open, open + 0.1 * (close - open), close};
  std::vector<std::vector<float>> steps;
  for (double t : times) steps.push_back(m.a.positionsAt(t));
  peer.build(steps);
  // A shutter over two keyframe segments: three keys, the middle one the keyframe.
  const double shutterOpen = m.a.times()[1] + 0.5 * (open - m.a.times()[1]);
  const std::vector<double> shutter =
      tsah::motion::shutterKeys(m.a.times(), shutterOpen, open + 0.25 * (close - open));
  ASSERT_EQ(shutter.size(), 3u);
  tsah::bench::EmbreeMotionPeer perFrame(m.a.indices(), m.a.vertexCount(), 2);
  EXPECT_GE(perFrame.build(m.a, shutter), 0.0);
  EXPECT_EQ(perFrame.timeSteps(), 3u);
  for (float tau : {0.1f, 0.5f, 0.9f}) {
    uint32_t shutterHits = 0;
    const double at = shutter.front() + double(tau) * (shutter.back() - shutter.front());
    EXPECT_GE(m.agreement(perFrame, at, tsah::bench::embreeStepTime(tsah::motion::keyFractions(shutter), tau),
                          &shutterHits),
              0.999)
        << "tau " << tau;
    EXPECT_GT(shutterHits, 30u);
  }
  const double time = open + 0.55 * (close - open);
  uint32_t hits = 0;
  const std::vector<float> keys = tsah::motion::keyFractions(times);
  EXPECT_GE(m.agreement(peer, time, tsah::bench::embreeStepTime(keys, 0.55f), &hits), 0.999);
  EXPECT_GT(hits, 100u);
  EXPECT_LT(m.agreement(peer, time, 0.55f, &hits), 0.99);  // the even mapping is wrong here
  EXPECT_THROW(peer.build(std::vector<std::vector<float>>{std::vector<float>(3)}), tsah::DataError);
}
namespace {

// The bench's setup on a small frame: 64x48, 4 AO and 2 shadow rays per pixel, frames at the
// given times, the camera fitted to the whole animation.
tsah::bench::RuntimeSetup smallSetup(const anim::Animation& a, std::vector<double> times) {
  return tsah::test::smallBenchSetup(a, std::move(times), 64, 48, 4);
}

}  // namespace

TEST(BenchMotionBlur, ThePartReportsEveryFieldAndEmbreeAgreesWithTheToolkit) {
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 1500, 6, 5);
  const tsah::Bvh tree = tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0));
  // Four frames over the animation with a centered shutter of 0.9: the middle frames' shutters
  // hold a keyframe (three keys or more), the clamped first and last frames two.
  const tsah::bench::RuntimeSetup setup = smallSetup(a, a.uniformTimes(4));
  const nlohmann::json j = tsah::bench::runMotionBlurComparison(a, tree, "toolkit", setup, {0.9, tsah::Shutter::Mode::Centered});
  EXPECT_EQ(j["shutter"]["fraction"], 0.9);
  EXPECT_EQ(j["shutter"]["mode"], "centered");
  EXPECT_EQ(j["frames"], 4);
  EXPECT_EQ(j["layout"], tsah::name(setup.layout));  // the CPU's default layout (bvh8 with AVX2)
  ASSERT_EQ(j["keys_per_frame"].size(), 4u);
  EXPECT_EQ(j["keys_per_frame"][0], 2);
  EXPECT_GE(j["keys_per_frame"][1].get<int>(), 3);
  EXPECT_EQ(j["embree_mb_build"]["time_steps"], a.keyframeCount());
  EXPECT_GE(j["embree_mb_build"]["ms"].get<double>(), 0.0);
  ASSERT_EQ(j["methods"].size(), 3u);
  const std::vector<std::string> names = {"tsah0-mb", "embree-mb", "embree-mb-rebuild"};
  for (std::size_t m = 0; m < 3; ++m) {
    const nlohmann::json& method = j["methods"][m];
    EXPECT_EQ(method["name"], names[m]);
    EXPECT_EQ(method["frames"], 4);
    EXPECT_GT(method["average"]["mrays_per_s"]["total"].get<double>(), 0.0) << names[m];
    EXPECT_GT(method["average"]["rays_per_frame"]["ao"].get<double>(), 0.0) << names[m];
    // The same rays for every tracer.
    EXPECT_EQ(method["average"]["rays_per_frame"]["total"], j["methods"][0]["average"]["rays_per_frame"]["total"]);
    if (m == 0) continue;
    const nlohmann::json& agreement = method["extra"]["agreement"];
    EXPECT_GE(agreement["fraction"].get<double>(), 0.999) << names[m] << ": " << agreement.dump();
    const nlohmann::json& d = agreement["differing"];
    EXPECT_EQ(agreement["rays"].get<uint64_t>() - agreement["same"].get<uint64_t>(),
              d["tie"].get<uint64_t>() + d["one_misses"].get<uint64_t>() + d["other_depth"].get<uint64_t>() +
                  d["occlusion"].get<uint64_t>());
    EXPECT_GT(agreement["primary"]["rays"].get<uint64_t>(), 0u);
  }
  // The toolkit's frame: update (refit at the keys) + trace; Embree's rebuild: build + trace.
  const nlohmann::json& own = j["methods"][0]["average"];
  EXPECT_NEAR(own["total_ms"].get<double>(), own["update_ms"].get<double>() + own["trace_ms"].get<double>(), 1e-9);
  EXPECT_GT(j["methods"][2]["average"]["update_ms"].get<double>(), 0.0);
  EXPECT_EQ(j["methods"][1]["average"]["update_ms"].get<double>(), 0.0);
  EXPECT_GT(j["ratios"]["toolkit_rate_over_embree_mb_rate"].get<double>(), 0.0);
  EXPECT_GT(j["ratios"]["toolkit_total_over_embree_rebuild_total"].get<double>(), 0.0);
}

// With a shutter of 1 each frame's shutter opens where the one before closed: the toolkit reuses
// that key and refits the others (keys_refitted_per_frame).
TEST(BenchMotionBlur, AShutterOfOneReusesTheKeyBetweenFrames) {
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 1500, 6, 5);
  const tsah::Bvh tree = tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0));
  const nlohmann::json j = tsah::bench::runMotionBlurComparison(a, tree, "toolkit", smallSetup(a, a.uniformTimes(5)),
                                                                {1.0, tsah::Shutter::Mode::Centered});
  const nlohmann::json &keys = j["keys_per_frame"], &refitted = j["keys_refitted_per_frame"];
  ASSERT_EQ(keys.size(), 5u);
  ASSERT_EQ(refitted.size(), 5u);
  EXPECT_EQ(refitted[0], keys[0]);
  for (std::size_t f = 1; f < 5; ++f) EXPECT_EQ(refitted[f].get<int>(), keys[f].get<int>() - 1) << "frame " << f;
}

// A mostly static animation: after the first frame, whose keys read every vertex, the bench's
// runtime refits its keys' moving parts only (keys_refitted_moving_only_per_frame).
TEST(BenchMotionBlur, KeysOfAMostlyStaticSceneRefitOnlyWhatMoves) {
  const anim::Animation a = tsah::test::mostlyStaticAnimation(3000, 500);
  const tsah::Bvh tree = tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0));
  const nlohmann::json j = tsah::bench::runMotionBlurComparison(a, tree, "toolkit", smallSetup(a, a.uniformTimes(4)),
                                                                {0.5, tsah::Shutter::Mode::Centered});
  const nlohmann::json &refitted = j["keys_refitted_per_frame"], &movingOnly = j["keys_refitted_moving_only_per_frame"];
  ASSERT_EQ(movingOnly.size(), 4u);
  EXPECT_LT(movingOnly[0].get<int>(), refitted[0].get<int>());
  for (std::size_t f = 1; f < 4; ++f) {
    EXPECT_GE(movingOnly[f].get<int>(), 1) << "frame " << f;
    EXPECT_LE(movingOnly[f].get<int>(), refitted[f].get<int>()) << "frame " << f;
  }
}

TEST(BenchMotionBlur, OneFrameOrNoShutterIsRefused) {
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 200, 3, 5);
  const tsah::Bvh tree = tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0));
  EXPECT_THROW(tsah::bench::runMotionBlurComparison(a, tree, "toolkit", smallSetup(a, {0.5}), {0.5}),
               tsah::ConfigError);
  EXPECT_THROW(tsah::bench::runMotionBlurComparison(a, tree, "toolkit", smallSetup(a, a.uniformTimes(3)), {0.0}),
               tsah::ConfigError);
}

TEST(BenchMotionBlur, AgreementClassifiesTheDifferences) {
  tsah::bench::BatchTrace own, other;
  auto hit = [](uint32_t tri, float t) {
    tsah::Hit h;
    h.tri = tri;
    h.t = t;
    return h;
  };
  own.closest = {hit(1, 2.0f), hit(2, 3.0f), hit(3, 4.0f), tsah::Hit{}, hit(5, 5.0f)};
  other.closest = {hit(1, 2.0f), hit(7, 3.0f), tsah::Hit{}, hit(4, 1.0f), hit(6, 9.0f)};
  own.aoResults = {1, 0, 1};
  other.aoResults = {1, 1, 1};
  own.shadowResults = {0};
  other.shadowResults = {0};
  tsah::bench::Agreement a;
  a.add(own, other);
  EXPECT_EQ(a.rays(), 9u);
  EXPECT_EQ(a.same(), 4u);
  EXPECT_EQ(a.ties, 1u);       // triangle 2 vs 7 at t 3
  EXPECT_EQ(a.oneMisses, 2u);  // 3 vs a miss, a miss vs 4
  EXPECT_EQ(a.otherDepth, 1u); // 5 at t 5 vs 6 at t 9
  EXPECT_EQ(a.occlusionRays - a.occlusionSame, 1u);
  EXPECT_DOUBLE_EQ(a.fraction(), 4.0 / 9.0);
}
#else
TEST(EmbreeMotionPeer, NeedsEmbree) { EXPECT_FALSE(tsah::bench::embreeAvailable()); }
#endif
