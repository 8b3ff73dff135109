// The CPU runtime end to end: a generated animation rendered with primary, AO and shadow rays,
// compared against a stored reference image; determinism across thread counts; ray accounting.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <limits>
#include <random>

#include "tsah/base/coordinates.hpp"
#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "test_support.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/layout/wide_bvh.hpp"
#include "tsah/layout/wide_tree.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/render/camera.hpp"
#include "tsah/render/camera_path.hpp"
#include "tsah/render/renderer.hpp"

namespace {

// A wide tree's topology: every node's child references and leaf triangle counts.
std::vector<int64_t> shapeOf(const tsah::WideTree<4>& tree) {
  std::vector<int64_t> shape;
  for (const auto& node : tree.nodes())
    for (uint32_t c = 0; c < 4; ++c) {
      shape.push_back(node.ref[c]);
      shape.push_back(node.count[c]);
    }
  return shape;
}

struct Scene {
  anim::Animation animation;
  tsah::FlatBvh tree;
  tsah::Aabb bounds;
};

Scene makeScene(anim::GeneratorKind kind, uint32_t triangles) {
  Scene s{tsah::test::generatedAnimation(kind, triangles, 6, 3), {}, {}};
  s.tree = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(s.animation, 0)));
  s.bounds = tsah::test::boxOf(s.animation.bounds());
  return s;
}

tsah::Image render(const Scene& s, double time, uint32_t threads, tsah::RenderSettings settings,
                   tsah::RenderStats* stats = nullptr, bool ground = true,
                   tsah::Layout layout = tsah::Layout::Bvh2) {
  tsah::CpuRuntime::Config config(threads);
  config.layout = layout;
  tsah::CpuRuntime rt(s.tree, {s.animation.indices().begin(), s.animation.indices().end()}, s.animation.vertexCount(),
                      config);
  rt.update(s.animation.positionsAt(time));
  const float aspect = float(settings.width) / float(settings.height);
  const tsah::Camera cam = tsah::fitCamera(s.bounds, {0, 1, 0}, 45.0f, aspect);
  const tsah::SceneLighting light = tsah::fitLighting(s.bounds, cam, {0, 1, 0}, 0.1f, ground);
  tsah::Image image;
  const tsah::RenderStats st = tsah::renderFrame(rt, cam, light, settings, image);
  if (stats) *stats = st;
  return image;
}

tsah::RenderSettings small(uint32_t w, uint32_t h) {
  tsah::RenderSettings r;
  r.width = w;
  r.height = h;
  r.aoSamples = 4;
  r.shadowSamples = 2;
  return r;
}

TEST(CpuRuntime, SameImageForAnyThreadCount) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 3000);
  const tsah::Image a = render(s, 2.5, 1, small(80, 60));
  const tsah::Image b = render(s, 2.5, 2, small(80, 60));
  const tsah::Image c = render(s, 2.5, 4, small(80, 60));
  EXPECT_EQ(a.rgb, b.rgb);
  EXPECT_EQ(a.rgb, c.rgb);
}

TEST(CpuRuntime, ImageFollowsTheAnimation) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 3000);
  const tsah::Image first = render(s, 0.0, 2, small(80, 60));
  const tsah::Image later = render(s, 4.0, 2, small(80, 60));
  const tsah::ImageDifference d = tsah::compareImages(first, later);
  EXPECT_GT(d.fractionAbove, 0.01);  // objects moved
}

TEST(CpuRuntime, RayAccounting) {
  const Scene s = makeScene(anim::GeneratorKind::Wave, 2000);
  tsah::RenderStats st;
  tsah::RenderSettings settings = small(64, 48);
  render(s, 1.0, 2, settings, &st, false);
  EXPECT_EQ(st.primary.rays, 64u * 48u);
  // Every pixel that hit the sheet cast exactly aoSamples AO rays; shadow rays at most shadowSamples.
  ASSERT_GT(st.ao.rays, 0u);
  EXPECT_EQ(st.ao.rays % settings.aoSamples, 0u);
  const uint64_t surfacePixels = st.ao.rays / settings.aoSamples;
  EXPECT_LE(surfacePixels, 64u * 48u);
  EXPECT_LE(st.shadow.rays, surfacePixels * settings.shadowSamples);
  EXPECT_EQ(st.total().rays, st.primary.rays + st.ao.rays + st.shadow.rays);
  // Without AO and shadow rays only primary rays are traced.
  settings.aoSamples = 0;
  settings.shadowSamples = 0;
  render(s, 1.0, 2, settings, &st, false);
  EXPECT_EQ(st.ao.rays, 0u);
  EXPECT_EQ(st.shadow.rays, 0u);
}

// The stored reference (tests/data/reference_wave_96x72.png) was rendered by this code; a change
// in traversal, refit, sampling or shading that alters the picture fails here. Regenerate it
// deliberately with TSAH_UPDATE_REFERENCE=1 after an intended change, and look at it.
TEST(CpuRuntime, MatchesReferenceImage) {
  const Scene s = makeScene(anim::GeneratorKind::Wave, 2000);
  const std::filesystem::path ref = std::filesystem::path(TSAH_SOURCE_DIR) / "tests/data/reference_wave_96x72.png";
  if (std::getenv("TSAH_UPDATE_REFERENCE")) {
    tsah::savePng(ref.string(), render(s, 2.5, 2, small(96, 72)));
    GTEST_SKIP() << "wrote " << ref;
  }
  ASSERT_TRUE(std::filesystem::exists(ref)) << ref << " is missing";
  const tsah::Image expected = tsah::loadPng(ref.string());
  // Every layout this processor traces renders the reference picture.
  for (tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
    if (!tsah::layoutSupported(layout)) continue;
    const tsah::Image image = render(s, 2.5, 2, small(96, 72), nullptr, true, layout);
    const tsah::ImageDifference d = tsah::compareImages(expected, image, 24);
    // Tolerance for floating-point differences between compilers and libm versions.
    EXPECT_LT(d.meanAbs, 1.5) << tsah::name(layout);
    EXPECT_LT(d.fractionAbove, 0.01) << tsah::name(layout);
    if (d.meanAbs >= 1.5 || d.fractionAbove >= 0.01)
      tsah::savePng((tsah::test::scratchDir() / (std::string("actual-") + tsah::name(layout) + ".png")).string(),
                    image);
  }
}

TEST(CpuRuntime, RejectsTreesDeeperThanTheStack) {
  // A caterpillar tree of 200 triangles is 199 levels deep.
  const uint32_t n = 200;
  std::vector<uint32_t> idx;
  std::vector<float> pos;
  for (uint32_t i = 0; i < n; ++i) {
    idx.insert(idx.end(), {3 * i, 3 * i + 1, 3 * i + 2});
    pos.insert(pos.end(), {float(i), 0, 0, float(i) + 1, 0, 0, float(i), 1, 0});
  }
  tsah::Bvh bvh;
  bvh.nodes.resize(2 * n - 1);
  for (uint32_t i = 0; i < n; ++i) bvh.primIds.push_back(i);
  // Interior node k (0..n-2) has leaf child n-1+k and interior child k+1 (the last one a leaf).
  for (uint32_t k = 0; k + 1 < n; ++k) {
    const uint32_t leaf = n - 1 + k;
    const uint32_t next = k + 2 < n ? k + 1 : 2 * n - 2;
    bvh.nodes[k].left = leaf;
    bvh.nodes[k].right = next;
    bvh.nodes[leaf].parent = k;
    bvh.nodes[next].parent = k;
    bvh.nodes[leaf].primBegin = k;
    bvh.nodes[leaf].primCount = 1;
  }
  bvh.nodes[2 * n - 2].primBegin = n - 1;
  bvh.nodes[2 * n - 2].primCount = 1;
  tsah::refit(bvh, tsah::triangleBoxes(idx, pos, 1));
  ASSERT_FALSE(tsah::validate(bvh));
  EXPECT_THROW(tsah::CpuRuntime(tsah::flattenBvh(bvh), idx, 3 * n), tsah::Error);
}

TEST(CpuRuntime, FittedCameraSeesTheWholeScene) {
  const Scene s = makeScene(anim::GeneratorKind::Explode, 1000);
  for (float aspect : {4.0f / 3.0f, 0.5f, 2.0f}) {
    const tsah::Camera cam = tsah::fitCamera(s.bounds, {0, 1, 0}, 45.0f, aspect);
    ASSERT_NO_THROW(tsah::validateCamera(cam));
    const uint32_t h = 100, w = uint32_t(100 * aspect);
    const tsah::CameraRays rays = tsah::cameraRays(cam, w, h);
    // Project every corner of the bounds: it must land inside the image.
    const tsah::Vec3 fwd = tsah::normalize(cam.lookAt - cam.eye);
    for (int c = 0; c < 8; ++c) {
      const tsah::Vec3 p{(c & 1) ? s.bounds.hi.x : s.bounds.lo.x, (c & 2) ? s.bounds.hi.y : s.bounds.lo.y,
                         (c & 4) ? s.bounds.hi.z : s.bounds.lo.z};
      const tsah::Vec3 d = p - cam.eye;
      ASSERT_GT(tsah::dot(d, fwd), 0.0f);
      // Solve corner + dx*px + dy*py = d / dot(d, fwd) in the image plane (dx, dy orthogonal).
      const tsah::Vec3 onPlane = d * (1.0f / tsah::dot(d, fwd)) - rays.corner;
      const float px = tsah::dot(onPlane, rays.dx) / tsah::dot(rays.dx, rays.dx);
      const float py = tsah::dot(onPlane, rays.dy) / tsah::dot(rays.dy, rays.dy);
      EXPECT_GE(px, 0.0f);
      EXPECT_LE(px, float(w));
      EXPECT_GE(py, 0.0f);
      EXPECT_LE(py, float(h));
    }
  }
}

TEST(CpuRuntime, CameraPathInterpolation) {
  std::vector<anim::CameraKey> keys(2);
  keys[0].time = 0.0;
  keys[0].eye = {0, 0, 10};
  keys[0].fovyDegrees = 40.0f;
  keys[1].time = 2.0;
  keys[1].eye = {10, 0, 0};
  keys[1].fovyDegrees = 60.0f;
  const tsah::Camera mid = tsah::cameraAt(keys, 1.0);
  EXPECT_FLOAT_EQ(mid.eye.x, 5.0f);
  EXPECT_FLOAT_EQ(mid.eye.z, 5.0f);
  EXPECT_FLOAT_EQ(mid.fovYDegrees, 50.0f);
  EXPECT_FLOAT_EQ(tsah::cameraAt(keys, -1.0).eye.z, 10.0f);  // clamped
  EXPECT_FLOAT_EQ(tsah::cameraAt(keys, 5.0).eye.x, 10.0f);
  EXPECT_THROW(tsah::cameraAt({}, 0.0), tsah::ConfigError);
  tsah::Camera bad;
  bad.lookAt = bad.eye;
  EXPECT_THROW(tsah::validateCamera(bad), tsah::ConfigError);
}

TEST(CpuRuntime, PngRoundTrip) {
  tsah::Image image(7, 5);
  for (std::size_t i = 0; i < image.rgb.size(); ++i) image.rgb[i] = uint8_t(i * 37);
  const auto bytes = tsah::encodePng(image);
  const tsah::Image back = tsah::decodePng(bytes, "mem.png");
  EXPECT_EQ(back.width, 7u);
  EXPECT_EQ(back.height, 5u);
  EXPECT_EQ(back.rgb, image.rgb);
  EXPECT_THROW(tsah::decodePng(std::vector<uint8_t>(bytes.begin(), bytes.begin() + 20), "cut.png"), tsah::FileError);
}

// A tree set read from a file collapses each tree into the wide layout with the objective of its
// own header, as the GPU runtime does; without build infos every tree takes the config's.
// The batch queries trace in the runtime's own layout: in bvh4 and bvh8 (every ISA this processor
// runs) they give the binary layout's hits, up to ties between triangles at the same distance.
TEST(CpuRuntime, BatchQueriesWorkInEveryLayout) {
  const Scene s = makeScene(anim::GeneratorKind::Explode, 3000);
  const std::vector<uint32_t> indices(s.animation.indices().begin(), s.animation.indices().end());
  const double t = s.animation.uniformTimes(3)[1];
  const auto runtimeIn = [&](tsah::Layout layout, std::optional<tsah::SimdIsa> isa) {
    tsah::CpuRuntime::Config config(2);
    config.layout = layout;
    config.isa = isa;
    auto rt = std::make_unique<tsah::CpuRuntime>(s.tree, indices, s.animation.vertexCount(), config);
    rt->update(s.animation.positionsAt(t));
    return rt;
  };
  // Rays from around the scene at random triangles' centres (every third one short, so that it may
  // end before the triangle).
  const std::vector<float> p = s.animation.positionsAt(t);
  const auto vertex = [&](uint32_t v) { return tsah::Vec3{p[3 * v], p[3 * v + 1], p[3 * v + 2]}; };
  std::vector<tsah::Ray> rays;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const tsah::Vec3 size = s.bounds.extent();
  for (int i = 0; i < 4000; ++i) {
    const uint32_t* tri = indices.data() + 3 * (rng() % s.animation.triangleCount());
    const tsah::Vec3 centre = (vertex(tri[0]) + vertex(tri[1]) + vertex(tri[2])) * (1.0f / 3.0f);
    tsah::Ray r;
    r.org = s.bounds.center() + tsah::Vec3{(u(rng) - 0.5f) * size.x, (u(rng) - 0.5f) * size.y, (u(rng) - 0.5f) * size.z} * 3.0f;
    r.dir = centre - r.org;
    r.tmin = 0.0f;
    r.tmax = i % 3 == 0 ? 0.5f : 3.4e38f;
    rays.push_back(r);
  }
  const auto binary = runtimeIn(tsah::Layout::Bvh2, std::nullopt);
  const std::vector<tsah::Hit> expected = tsah::closestHits(*binary, rays);
  const std::vector<uint8_t> expectedAny = tsah::anyHits(*binary, rays);
  uint32_t hits = 0;
  for (const tsah::Hit& h : expected) hits += h.valid() ? 1 : 0;
  ASSERT_GT(hits, rays.size() / 2);  // a meaningful batch
  for (const tsah::SimdIsa isa : {tsah::SimdIsa::Sse, tsah::SimdIsa::Avx2, tsah::SimdIsa::Avx512}) {
    for (const tsah::Layout layout : {tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
      std::unique_ptr<tsah::CpuRuntime> wide;
      try {
        wide = runtimeIn(layout, isa);
      } catch (const tsah::ConfigError&) {
        continue;  // this processor does not run these kernels
      }
      const std::string what = std::string(tsah::name(layout)) + " " + tsah::name(isa);
      const std::vector<tsah::Hit> got = tsah::closestHits(*wide, rays);
      const std::vector<uint8_t> any = tsah::anyHits(*wide, rays);
      uint32_t ties = 0;
      for (std::size_t i = 0; i < rays.size(); ++i) {
        ASSERT_EQ(got[i].valid(), expected[i].valid()) << what << " ray " << i;
        EXPECT_EQ(any[i], expectedAny[i]) << what << " ray " << i;
        if (!got[i].valid()) continue;
        EXPECT_NEAR(got[i].t, expected[i].t, 1e-5f * std::max(1.0f, expected[i].t)) << what << " ray " << i;
        ties += got[i].tri != expected[i].tri ? 1 : 0;
      }
      EXPECT_LE(ties, hits / 100) << what << ": other triangles at the same distance";
    }
  }
}

TEST(CpuRuntime, TreeSetCollapsesEachTreeWithItsOwnObjective) {
  const tsah::test::WideObjectiveCase c = tsah::test::wideObjectiveCase();
  const anim::Animation& a = c.animation;
  const tsah::TreeSet set = tsah::test::twoPartObjectiveSet(c);  // tree 1 keeps the default objective
  tsah::CpuRuntime::Config config(1);
  config.layout = tsah::Layout::Bvh4;  // SSE kernels: every x86-64 processor runs them
  config.isa = tsah::SimdIsa::Sse;
  const tsah::Objective given{1, {2.0f, 1.0f}, 3};
  config.collapse = tsah::wideCollapseConfig(given);
  // The wide tree the runtime should hold: its child references and leaf counts.
  const auto expectedShape = [&](const tsah::Objective& objective) {
    tsah::WideCollapser::Config w = tsah::wideCollapseConfig(objective, 4);
    w.leafPacket = 4;
    const tsah::WideTree<4> tree(tsah::WideCollapser(w).collapse(tsah::unflattenBvh(c.tree)), a.indices(), 1,
                                 tsah::SimdIsa::Sse);
    return shapeOf(tree);
  };
  const tsah::Objective own[2] = {c.objective, tsah::Objective{}};
  for (const tsah::Objective& o : own) ASSERT_NE(expectedShape(o), expectedShape(given));  // a meaningful input
  tsah::TreeSet bare = set;
  bare.builds.clear();
  const std::vector<uint32_t> indices(a.indices().begin(), a.indices().end());
  tsah::CpuRuntime withBuilds(set, indices, a.vertexCount(), config);
  tsah::CpuRuntime withoutBuilds(bare, indices, a.vertexCount(), config);
  for (double t : {a.startTime(), a.endTime()}) {
    const uint32_t s = set.treeAt(t);
    for (tsah::CpuRuntime* runtime : {&withBuilds, &withoutBuilds}) {
      const bool builds = runtime == &withBuilds;
      runtime->selectTreeAt(t);
      ASSERT_EQ(runtime->currentTree(), s);
      EXPECT_EQ(shapeOf(*runtime->wide4()), expectedShape(builds ? own[s] : given)) << "t=" << t << " builds " << builds;
    }
  }
  tsah::TreeSet partial = set;
  partial.builds.resize(1);
  EXPECT_THROW(tsah::CpuRuntime(partial, indices, a.vertexCount(), config), tsah::DataError);
}

}  // namespace


namespace {

// The frame blurred over the shutter [open, close] of the animation (tsah::updateShutter).
tsah::Image renderBlurred(const Scene& s, double open, double close, uint32_t threads,
                          const tsah::RenderSettings& settings) {
  tsah::CpuRuntime rt(s.tree, {s.animation.indices().begin(), s.animation.indices().end()}, s.animation.vertexCount(),
                      tsah::CpuRuntime::Config(threads));
  tsah::updateShutter(rt, s.animation, open, close);
  const float aspect = float(settings.width) / float(settings.height);
  const tsah::Camera cam = tsah::fitCamera(s.bounds, {0, 1, 0}, 45.0f, aspect);
  const tsah::SceneLighting light = tsah::fitLighting(s.bounds, cam, {0, 1, 0}, 0.1f, true);
  tsah::Image image;
  tsah::renderFrame(rt, cam, light, settings, image);
  return image;
}

}  // namespace

TEST(CpuRuntime, AClosedShutterGivesTheInstantImage) {
  const Scene s = makeScene(anim::GeneratorKind::Swap, 3000);
  EXPECT_EQ(renderBlurred(s, 2.5, 2.5, 2, small(80, 60)).rgb, render(s, 2.5, 2, small(80, 60)).rgb);
}

TEST(CpuRuntime, BlurredImageMixesTheShutterAndIsDeterministic) {
  // Each pixel sees the scene at its own time in [2, 3]: unlike the instant at either end, and the
  // same picture for any thread count.
  const Scene s = makeScene(anim::GeneratorKind::Swap, 3000);
  const tsah::Image blurred = renderBlurred(s, 2.0, 3.0, 1, small(80, 60));
  EXPECT_EQ(blurred.rgb, renderBlurred(s, 2.0, 3.0, 2, small(80, 60)).rgb);
  EXPECT_EQ(blurred.rgb, renderBlurred(s, 2.0, 3.0, 4, small(80, 60)).rgb);
  for (double instant : {2.0, 3.0})
    EXPECT_GT(tsah::compareImages(blurred, render(s, instant, 2, small(80, 60))).fractionAbove, 0.002) << instant;
}

// A caller's buffer passes the check an imported animation passes: the count, then every
// coordinate finite and within tsah::kMaxCoordinate, one DataError naming the vertex.
TEST(CpuRuntime, UpdateRefusesBadCallerPositions) {
  const Scene s = makeScene(anim::GeneratorKind::Explode, 200);
  tsah::CpuRuntime rt(s.tree, {s.animation.indices().begin(), s.animation.indices().end()}, s.animation.vertexCount(),
                      tsah::CpuRuntime::Config(1));
  const std::vector<float> good = s.animation.positionsAt(0.0);
  const auto messageOf = [&](std::vector<float> positions) {
    try {
      rt.update(positions);
    } catch (const tsah::DataError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(messageOf(std::vector<float>(good.begin(), good.end() - 3)),
            "runtime: got " + std::to_string(good.size() - 3) + " coordinates, expected " + std::to_string(good.size()));
  std::vector<float> bad = good;
  bad[3 * 7 + 1] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(messageOf(bad), "runtime: vertex 7 has a NaN or infinite coordinate");
  bad = good;
  bad[3 * 5] = -1e30f;
  EXPECT_EQ(messageOf(bad), "runtime: vertex 5 has coordinate -1e+30, beyond the supported magnitude 1e+18 "
                            "(surface areas would overflow)");
  bad[3 * 5] = tsah::kMaxCoordinate;  // the limit itself is accepted
  EXPECT_EQ(messageOf(bad), "no error");
}
