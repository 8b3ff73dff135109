// The two-level part of the bench (bench/two_level_bench.hpp): Embree instancing (one scene per
// static source and per pose, instances committed in a top level every frame) finds what the
// toolkit's two-level runtime finds, refits only the poses whose local time changed, and skips an
// instance whose path flattens it; the report renders the part.
#include <gtest/gtest.h>

#include <array>
#include <random>

#include "bench/embree_instanced.hpp"
#include "bench/embree_peer.hpp"
#include "bench/report.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "test_support.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

#if TSAH_HAVE_EMBREE
// Runs body on the calling thread (the peer's poses one after another).
void serial(std::size_t n, const std::function<void(std::size_t, std::size_t)>& body) { body(0, n); }

tsah::Hit embreeHit(const tsah::bench::BatchTracer& tracer, const tsah::Ray& ray) {
  tsah::Hit hit;
  tracer.closest(&ray, nullptr, 1, &hit);
  return hit;
}

TEST(BenchEmbreeInstanced, FindsWhatTheTwoLevelRuntimeFindsAtEveryTime) {
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeTwoLevelScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  tsah::TwoLevelRuntime runtime(s, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  tsah::bench::EmbreeInstancedPeer embree(s, 2, serial);
  embree.build(s.frameTimes.front());
  EXPECT_EQ(embree.objectScenes(), 1u + s.poses.size());  // the static ground, and every pose
  const tsah::bench::BatchTracer tracer = embree.tracer();
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> around(-12.0f, 12.0f);
  uint64_t rays = 0, same = 0, hits = 0;
  for (std::size_t f = 0; f < s.frameTimes.size(); f += 3) {
    const double t = s.frameTimes[f];
    runtime.update(t);
    embree.update(t);
    const auto boxes = runtime.instanceBoxes();
    for (int r = 0; r < 300; ++r) {
      // From a random point around the scene to the centre of a random instance's box.
      const tsah::Aabb& box = boxes[std::size_t(rng() % boxes.size())];
      tsah::Ray ray;
      ray.org = {around(rng), around(rng), around(rng)};
      ray.dir = (box.lo + box.hi) * 0.5f - ray.org;
      ray.tmin = 0.0f;
      ray.tmax = 1e30f;
      const tsah::TwoLevelHit own = runtime.closestHit(ray);
      const tsah::Hit other = embreeHit(tracer, ray);
      uint8_t occluded = 0;
      tracer.occluded(&ray, nullptr, 1, tsah::AnyHitOrder::TreeOrder, &occluded);
      ++rays;
      hits += own.valid() ? 1 : 0;
      EXPECT_EQ(own.valid(), bool(occluded)) << "t " << t;
      if (own.valid() != other.valid()) continue;
      if (!own.valid() || (s.scene.bakedTriangle(own.instance, own.prim) == other.tri &&
                           std::abs(own.t - other.t) <= 1e-4f * std::max(own.t, other.t)))
        ++same;
    }
  }
  EXPECT_GT(hits, rays / 4);  // the rays meet the scene
  // Two watertight tests round differently on rays grazing an edge: a few may differ.
  EXPECT_GE(double(same), 0.995 * double(rays)) << same << " of " << rays;
}

TEST(BenchEmbreeInstanced, RefitsOnlyThePosesWhoseLocalTimeChanged) {
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeRigidPathScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  tsah::bench::EmbreeInstancedPeer embree(s, 2, serial);
  embree.build(0.0);
  embree.update(3.0);
  EXPECT_EQ(embree.lastUpdateRefits(), 2u);
  embree.update(5.0);  // both poses reach their last frame (local time 4)
  EXPECT_EQ(embree.lastUpdateRefits(), 2u);
  for (const double t : {6.0, 7.0, 8.0}) {  // and hold it while the path moves on
    embree.update(t);
    EXPECT_EQ(embree.lastUpdateRefits(), 0u) << "t " << t;
  }
}

TEST(BenchEmbreeInstanced, AnInstanceFlattenedByItsPathIsNotHitThenAndIsAfter) {
  const fs::path dir = tsah::test::scratchDir();
  // At t = 1 the instance is flat (a singular world transform).
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeFlattenedTriangleScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  tsah::bench::EmbreeInstancedPeer embree(s, 2, serial);
  embree.build(0.0);
  tsah::Ray across;  // along x through (x, 1/3, 1/3)
  across.org = {-2.0f, 1.0f / 3.0f, 1.0f / 3.0f};
  across.dir = {1.0f, 0.0f, 0.0f};
  across.tmin = 0.0f;
  across.tmax = 10.0f;
  embree.update(1.0);
  EXPECT_FALSE(embreeHit(embree.tracer(), across).valid());
  embree.update(2.0);  // mirrored: (-1,0,0) (0,1,0) (0,0,1), crossed at x = -1/3
  const tsah::Hit hit = embreeHit(embree.tracer(), across);
  ASSERT_TRUE(hit.valid());
  EXPECT_NEAR(hit.t, 2.0f - 1.0f / 3.0f, 1e-5f);
}
#else
TEST(BenchEmbreeInstanced, StatusSaysEmbreeIsMissing) { EXPECT_FALSE(tsah::bench::embreeAvailable()); }
#endif

TEST(BenchTwoLevelReport, TablesOfThePartAndASkippedPart) {
  using nlohmann::json;
  const json agreement = {{"rays", 100}, {"same", 99}, {"fraction", 0.99},
                          {"differing", {{"tie", 1}, {"one_misses", 0}, {"other_depth", 0}, {"occlusion", 0}}}};
  auto method = [](const char* name, const char* label, double total) {
    return json{{"name", name},
                {"label", label},
                {"average", {{"update_ms", 1.0}, {"trace_ms", total - 1.0}, {"total_ms", total},
                             {"mrays_per_s", {{"primary", 2.0}, {"ao", 3.0}, {"shadow", 4.0}, {"total", 3.0}}}}}};
  };
  json two = method("two-level", "two-level (TLAS refit)", 8.0);
  two["extra"] = {{"agreement_with_flat", agreement}};
  const json part = {{"instances", 7}, {"sources", 3}, {"static_sources", 2}, {"poses", 2}, {"tlas_trees", 4}, {"frames", 5},
                     {"width", 64}, {"height", 48}, {"ao_rays", 8}, {"shadow_rays", 2}, {"layout", "bvh8"},
                     {"threads", 2}, {"embree_status", "3.13.5"},
                     {"optimize", {{"flat", {{"wall_s", 2.0}, {"peak_rss_bytes", 3.0 * 1048576}}},
                                   {"two_level", {{"wall_s", 1.0}, {"peak_rss_bytes", 2.0 * 1048576}}}}},
                     {"methods", json::array({method("flat", "flat tree", 10.0), two,
                                              method("embree-instanced", "Embree instancing", 16.0)})},
                     {"ratios", {{"two_level_rate_over_flat_rate", 1.0}, {"two_level_total_over_flat_total", 0.8},
                                 {"two_level_total_over_embree_total", 0.5}}}};
  // One tsah_two_level_gpu_bench report: the two-level medians {update, BLAS, TLAS, primary, AO}, the
  // flat tree's {update, primary, AO} and the trace rate.
  auto gpuRun = [](std::array<double, 5> medians, std::array<double, 3> flatMedians, double rate) {
    return json{{"median", {{"update_ms", medians[0]}, {"blas_refit_ms", medians[1]}, {"tlas_update_ms", medians[2]},
                            {"primary_ms", medians[3]}, {"ao_ms", medians[4]}}},
                {"flat",
                 {{"median", {{"update_ms", flatMedians[0]}, {"primary_ms", flatMedians[1]}, {"ao_ms", flatMedians[2]}}},
                  {"trace_rate_two_level_over_flat", rate}}}};
  };
  json withGpu = part;
  withGpu["gpu"] = gpuRun({0.5, 0.3, 0.1, 1.0, 2.0}, {6.0, 1.5, 2.5}, 1.25);
  withGpu["gpu"]["device"] = "NVIDIA H100";
  withGpu["gpu"]["ao_per_hit"] = 8;
  withGpu["gpu"]["median"]["tlas_rebuild_cpu_ms"] = 4.0;
  const std::string gpu = tsah::bench::twoLevelSection({{"name", "town"}, {"two_level", withGpu}});
  EXPECT_NE(gpu.find("GPU (NVIDIA H100, tsah_two_level_gpu_bench: its own rays, one primary per pixel and 8 AO per hit; "
                     "medians): two-level update 0.500 ms (BLAS refits 0.300, TLAS 0.100), primary + AO 3.00 ms; flat "
                     "update 6.00 ms, primary + AO 4.00 ms; trace rate two-level / flat 1.25; host TLAS rebuild 4.00 ms"),
            std::string::npos)
      << gpu;
  // Without a TLAS rebuild compared the paragraph ends there; with them, one sentence of frame totals.
  EXPECT_EQ(gpu.find("GPU frame total"), std::string::npos) << gpu;
  auto tlasRun = [](const char* update, double tlasMs, double frameMs, int unlike) {
    return json{{"update", update},
                {"median", {{"tlas_update_ms", tlasMs}, {"primary_ms", 1.0}, {"ao_ms", 2.0}, {"frame_ms", frameMs}}},
                {"primary_hits_unlike_refit", unlike}};
  };
  withGpu["gpu"]["tlas"] = json::array({tlasRun("refit", 0.01, 3.51, 0), tlasRun("lbvh", 0.05, 3.6, 0),
                                        tlasRun("hlbvh-sah", 0.07, 3.64, 2)});
  const std::string rebuilt = tsah::bench::twoLevelSection({{"name", "town"}, {"two_level", withGpu}});
  EXPECT_NE(rebuilt.find("host TLAS rebuild 4.00 ms per frame. GPU frame total (update + primary + AO, medians) with "
                         "the TLAS refitted 3.51 ms (TLAS 0.0100 ms, trace 3.00 ms), rebuilt by lbvh 3.60 ms (TLAS "
                         "0.0500 ms, trace 3.00 ms, primary hits unlike the refit's 0), rebuilt by hlbvh-sah 3.64 ms "
                         "(TLAS 0.0700 ms, trace 3.00 ms, primary hits unlike the refit's 2).\n\n"),
            std::string::npos)
      << rebuilt;
  // The compressed layout's run follows in the same paragraph; without it the paragraph ends above.
  EXPECT_EQ(rebuilt.find("compressed layout"), std::string::npos) << rebuilt;
  withGpu["gpu_cwbvh"] = gpuRun({0.7, 0.5, 0.1, 1.2, 1.8}, {5.0, 1.0, 2.0}, 0.9);
  const std::string compressed = tsah::bench::twoLevelSection({{"name", "town"}, {"two_level", withGpu}});
  EXPECT_NE(compressed.find("(TLAS 0.0700 ms, trace 3.00 ms, primary hits unlike the refit's 2). BLAS and flat tree in "
                            "the compressed layout (cwbvh): two-level update 0.700 ms (BLAS refits 0.500, TLAS 0.100), "
                            "primary + AO 3.00 ms; flat update 5.00 ms, primary + AO 3.00 ms; trace rate two-level / "
                            "flat 0.90.\n\n"),
            std::string::npos)
      << compressed;
  const json scene = {{"name", "town"}, {"two_level", part}};
  const std::string section = tsah::bench::twoLevelSection(scene);
  EXPECT_NE(section.find("**Two-level part** (7 instances of 3 sources (2 static), 2 poses, 4 TLAS tree(s) over the scene's time; 5"), std::string::npos) << section;
  EXPECT_NE(section.find("flat 2.00 s, 3.00 MiB; two-level 1.00 s, 2.00 MiB"), std::string::npos) << section;
  EXPECT_NE(section.find("| two-level (TLAS refit) | 1.00 | 3.00 | 8.00 | 2.00 / 3.00 / 4.00 | 99.000% (1 of 100"),
            std::string::npos)
      << section;
  EXPECT_NE(section.find("two-level frame total / Embree instancing's: 0.50"), std::string::npos) << section;
  const std::string summary = tsah::bench::twoLevelSummary(json::array({scene}));
  EXPECT_NE(summary.find("| town | 7 | 2.00 s, 3.00 MiB | 1.00 s, 2.00 MiB | 10.0 | 1.00 | 8.00 | 1.00 | 16.0 | 1.00 | 0.50 |"),
            std::string::npos)
      << summary;
  const json skipped = {{"name", "town"}, {"two_level", {{"skipped", "runs on the CPU"}}}};
  EXPECT_EQ(tsah::bench::twoLevelSection(skipped), "**Two-level part:** skipped (runs on the CPU).\n\n");
  EXPECT_EQ(tsah::bench::twoLevelSummary(json::array({skipped})), "");
}

}  // namespace
