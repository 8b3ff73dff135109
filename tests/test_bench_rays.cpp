// The bench's ray batches (bench/ray_batch.hpp) hold exactly the rays renderFrame traces, are traced
// correctly in parallel chunks, and Embree (bench/embree_peer.hpp, when built) finds what the
// toolkit finds on them, after rebuilds and after refits.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <mutex>
#include <set>
#include <thread>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "bench/embree_peer.hpp"
#include "bench/ray_batch.hpp"
#include "tsah/optimize/baselines.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/render/sampling.hpp"
#include "test_support.hpp"

namespace {

struct Scene {
  anim::Animation a;
  tsah::Bvh tree;
  tsah::Aabb bounds;

  explicit Scene(anim::GeneratorKind kind) {
    a = tsah::test::generatedAnimation(kind, 1500, 6, 11);
    const anim::Animation rep = a.resample(3);
    tsah::BaselineConfig config;
    config.threads = 2;
    tree = tsah::buildSah0(tsah::triangleBoxes(rep.indices(), rep.allPositions(), 3), config);
    bounds = tsah::test::boxOf(a.bounds());
  }
  tsah::CpuRuntime runtime() const {
    return tsah::CpuRuntime(tsah::flattenBvh(tree), {a.indices().begin(), a.indices().end()}, a.vertexCount(), {2});
  }
};

tsah::RenderSettings smallSettings(uint32_t frame) {
  tsah::RenderSettings s;
  s.width = 64;
  s.height = 48;
  s.aoSamples = 5;
  s.shadowSamples = 3;
  s.frame = frame;
  s.seed = 7;
  return s;
}

TEST(BenchRays, SmallPassesRunInEnoughTasksForEveryThread) {
  using tsah::bench::raysPerTask;
  EXPECT_EQ(raysPerTask(786432), 4096u);                          // a 1024x768 primary pass
  EXPECT_EQ((21390 + raysPerTask(21390) - 1) / raysPerTask(21390), 128u);  // horses8m's shadow pass
  EXPECT_EQ(raysPerTask(8192), 64u);
  EXPECT_EQ(raysPerTask(100), 64u);  // a tiny pass: tasks of at least 64 rays
}

TEST(BenchRays, StartWorkersReturnsOnceEveryThreadRanATask) {
  const Scene scene(anim::GeneratorKind::Wave);
  const tsah::CpuRuntime rt = scene.runtime();
  const tsah::bench::Workers own = tsah::bench::workersOf(rt);
  std::mutex mutex;
  std::set<std::thread::id> ran;  // the threads that ran a task of the last call
  const tsah::bench::Workers recorded{
      [&](std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body) {
        own.parallelFor(n, grain, [&](std::size_t begin, std::size_t end) {
          {
            const std::lock_guard<std::mutex> lock(mutex);
            ran.insert(std::this_thread::get_id());
          }
          body(begin, end);
        });
      },
      own.threads};
  // The bench's 20 ms is often too short for a worker of a busy 2-core machine (a build beside the
  // tests) to be scheduled: the test waits up to 30 s.
  ASSERT_TRUE(tsah::bench::startWorkers(recorded, std::chrono::seconds(30)));
  EXPECT_EQ(ran.size(), rt.threadCount());
}

TEST(BenchRays, TheBatchHoldsTheRenderersRaysAndTracesLikeOneLoop) {
  const Scene scene(anim::GeneratorKind::Wave);
  tsah::CpuRuntime rt = scene.runtime();
  for (bool ground : {false, true}) {
    for (uint32_t frame : {0u, 4u}) {
      rt.update(scene.a.positionsAt(scene.a.times()[frame]));
      const tsah::Camera camera = tsah::fitCamera(scene.bounds, {0, 1, 0}, 45.0f, 64.0f / 48.0f);
      const tsah::SceneLighting lighting = tsah::fitLighting(scene.bounds, camera, {0, 1, 0}, 0.1f, ground);
      const tsah::RenderSettings settings = smallSettings(frame);
      tsah::Image image;
      const tsah::RenderStats stats = tsah::renderFrame(rt, camera, lighting, settings, image);
      const tsah::bench::RayBatch batch = tsah::bench::makeRayBatch(rt, camera, lighting, settings);
      EXPECT_EQ(batch.primary.size(), stats.primary.rays) << "ground " << ground << " frame " << frame;
      EXPECT_EQ(batch.ao.size(), stats.ao.rays) << "ground " << ground << " frame " << frame;
      EXPECT_EQ(batch.shadow.size(), stats.shadow.rays) << "ground " << ground << " frame " << frame;
      EXPECT_GT(batch.ao.size(), 0u);
      EXPECT_GT(batch.shadow.size(), 0u);
      // Made again: the same rays (deterministic whatever the scheduling).
      const tsah::bench::RayBatch again = tsah::bench::makeRayBatch(rt, camera, lighting, settings);
      ASSERT_EQ(again.ao.size(), batch.ao.size());
      EXPECT_EQ(std::memcmp(again.ao.data(), batch.ao.data(), batch.ao.size() * sizeof(tsah::Ray)), 0);
      ASSERT_EQ(again.shadow.size(), batch.shadow.size());
      EXPECT_EQ(std::memcmp(again.shadow.data(), batch.shadow.data(), batch.shadow.size() * sizeof(tsah::Ray)), 0);

      const tsah::bench::BatchTrace t = tsah::bench::traceBatch(rt, batch, tsah::bench::toolkitTracer(rt));
      uint64_t hits = 0, aoOccluded = 0, shadowOccluded = 0;
      const tsah::BvhView view = rt.view();
      for (const tsah::Ray& r : batch.primary) hits += tsah::closestHit(view, r).valid();
      for (const tsah::Ray& r : batch.ao) aoOccluded += tsah::anyHit(view, r);
      for (const tsah::Ray& r : batch.shadow) shadowOccluded += tsah::anyHit(view, r);
      EXPECT_EQ(t.primaryHits, hits);
      EXPECT_EQ(t.aoOccluded, aoOccluded);
      EXPECT_EQ(t.shadowOccluded, shadowOccluded);
      EXPECT_EQ(t.total().rays, batch.rays());
      EXPECT_GT(hits, 0u);
      EXPECT_GT(aoOccluded, 0u);
    }
  }
}

TEST(BenchRays, ABlurredFramesBatchHoldsTheRenderersRaysAtEachPixelsTime) {
  // A wave over a shutter of two keyframe intervals (three keys).
  const Scene scene(anim::GeneratorKind::Wave);
  tsah::CpuRuntime rt = scene.runtime();
  tsah::updateShutter(rt, scene.a, scene.a.times()[2], scene.a.times()[4]);
  ASSERT_TRUE(rt.blurred());
  const tsah::Aabb now = tsah::test::boxOf(scene.a.boundsAt(scene.a.times()[3]));
  const tsah::Camera camera = tsah::fitCamera(now, {0, 1, 0}, 45.0f, 64.0f / 48.0f);
  const tsah::SceneLighting lighting = tsah::fitLighting(now, camera, {0, 1, 0}, 0.1f, false);
  const tsah::RenderSettings settings = smallSettings(3);
  tsah::Image image;
  const tsah::RenderStats stats = tsah::renderFrame(rt, camera, lighting, settings, image);
  const tsah::bench::RayBatch batch = tsah::bench::makeRayBatch(rt, camera, lighting, settings);
  EXPECT_EQ(batch.primary.size(), stats.primary.rays);
  EXPECT_EQ(batch.ao.size(), stats.ao.rays);
  EXPECT_EQ(batch.shadow.size(), stats.shadow.rays);
  ASSERT_GT(batch.ao.size(), 0u);
  ASSERT_EQ(batch.times.primary.size(), batch.primary.size());
  ASSERT_EQ(batch.times.ao.size(), batch.ao.size());
  ASSERT_EQ(batch.times.shadow.size(), batch.shadow.size());
  for (std::size_t i = 0; i < batch.primary.size(); ++i)
    ASSERT_EQ(batch.times.primary[i], tsah::pixelShutterTime({settings.seed, settings.frame, uint32_t(i)}));
  // The AO rays of a pixel share its time: aoSamples in a row with the same time.
  for (std::size_t i = 0; i < batch.ao.size(); i += settings.aoSamples)
    for (uint32_t k = 1; k < settings.aoSamples; ++k) ASSERT_EQ(batch.times.ao[i + k], batch.times.ao[i]);

  // Traced at the rays' times: each result is the runtime's own query at that time.
  const tsah::bench::BatchTrace t = tsah::bench::traceBatch(rt, batch, tsah::bench::toolkitTracer(rt));
  ASSERT_EQ(t.closest.size(), batch.primary.size());
  uint64_t hits = 0;
  for (std::size_t i = 0; i < batch.primary.size(); ++i) {
    const tsah::Hit h = rt.closestHit(batch.primary[i], batch.times.primary[i]);
    ASSERT_EQ(t.closest[i].tri, h.tri) << "ray " << i;
    hits += h.valid();
  }
  for (std::size_t i = 0; i < batch.ao.size(); ++i)
    ASSERT_EQ(t.aoResults[i], rt.anyHit(batch.ao[i], batch.times.ao[i], tsah::AnyHitOrder::TreeOrder) ? 1 : 0);
  EXPECT_EQ(t.primaryHits, hits);
  EXPECT_GT(hits, 100u);
  // Other times of the right shape are taken; a batch with times of another shape is refused.
  tsah::bench::RayTimes wrong = batch.times;
  wrong.ao.pop_back();
  EXPECT_THROW(tsah::bench::traceBatch(rt, batch, tsah::bench::toolkitTracer(rt), &wrong), tsah::ConfigError);
}

#if TSAH_HAVE_EMBREE
TEST(BenchRays, EmbreeFindsWhatTheToolkitFindsAfterRebuildsAndRefits) {
  // Fragments flying apart: a stale (not refitted) tree would miss most of them in later frames.
  const Scene scene(anim::GeneratorKind::Explode);
  tsah::CpuRuntime rt = scene.runtime();
  using Mode = tsah::bench::EmbreePeer::Mode;
  for (Mode mode : {Mode::RebuildMedium, Mode::RebuildHigh, Mode::Refit}) {
    tsah::bench::EmbreePeer peer(scene.a.indices(), scene.a.vertexCount(), mode, 2);
    for (uint32_t frame : {0u, 3u, 5u}) {
      const std::vector<float> positions = scene.a.positionsAt(scene.a.times()[frame]);
      rt.update(positions);
      EXPECT_GE(peer.update(positions), 0.0);
      // Framed on this frame's fragments, so that most pixels see some.
      const tsah::Aabb now = tsah::test::boxOf(scene.a.boundsAt(scene.a.times()[frame]));
      const tsah::Camera camera = tsah::fitCamera(now, {0, 1, 0}, 45.0f, 64.0f / 48.0f);
      const tsah::SceneLighting lighting = tsah::fitLighting(now, camera, {0, 1, 0}, 0.1f, false);
      const tsah::bench::RayBatch batch = tsah::bench::makeRayBatch(rt, camera, lighting, smallSettings(frame));
      const auto own = tsah::bench::traceBatch(rt, batch, tsah::bench::toolkitTracer(rt));
      const auto other = tsah::bench::traceBatch(rt, batch, peer.tracer());
      ASSERT_GT(own.primaryHits, 10u) << "frame " << frame;
      // Both are correct ray tracers; they may differ only on rays that graze an edge.
      const auto close = [](uint64_t x, uint64_t y, uint64_t of) {
        return std::max(x, y) - std::min(x, y) <= std::max<uint64_t>(2, of / 500);
      };
      const char* name = tsah::bench::EmbreePeer::modeName(mode);
      EXPECT_TRUE(close(own.primaryHits, other.primaryHits, batch.primary.size()))
          << name << " frame " << frame << ": " << own.primaryHits << " vs " << other.primaryHits;
      EXPECT_TRUE(close(own.aoOccluded, other.aoOccluded, batch.ao.size()))
          << name << " frame " << frame << ": " << own.aoOccluded << " vs " << other.aoOccluded;
      EXPECT_TRUE(close(own.shadowOccluded, other.shadowOccluded, batch.shadow.size()))
          << name << " frame " << frame << ": " << own.shadowOccluded << " vs " << other.shadowOccluded;
      // Rays aimed at every 7th triangle's centroid hit something, for both.
      std::vector<tsah::Ray> aimed;
      const auto idx = scene.a.indices();
      for (uint32_t t = 0; t < scene.a.triangleCount(); t += 7) {
        tsah::Vec3 c{0, 0, 0};
        for (int k = 0; k < 3; ++k)
          c = c + tsah::Vec3{positions[3 * idx[3 * t + k]], positions[3 * idx[3 * t + k] + 1],
                             positions[3 * idx[3 * t + k] + 2]} * (1.0f / 3.0f);
        aimed.push_back({camera.eye, 0.0f, c - camera.eye, 1.001f});
      }
      std::vector<tsah::Hit> aimedHits(aimed.size());
      peer.tracer().closest(aimed.data(), nullptr, aimed.size(), aimedHits.data());
      EXPECT_EQ(std::count_if(aimedHits.begin(), aimedHits.end(), [](const tsah::Hit& h) { return h.valid(); }),
                std::ptrdiff_t(aimed.size()))
          << name << " frame " << frame;
    }
    EXPECT_THROW(peer.update(std::vector<float>(3)), tsah::Error);
  }
}
#else
TEST(BenchRays, EmbreeIsReportedMissing) {
  EXPECT_FALSE(tsah::bench::embreeAvailable());
  EXPECT_NE(tsah::bench::embreeStatus().find("missing"), std::string::npos);
}
#endif

}  // namespace
