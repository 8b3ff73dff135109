// Two-level scenes (docs/two-level.md): one BLAS per source, poses, a TLAS optimized over the
// scene's frames, and the CPU runtime, checked against the flat baked scene.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "anim/scene.hpp"
#include "anim/tanim.hpp"
#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/core/instance_transform.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "test_support.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

using tsah::test::writeText;

// Relative tolerance on the hit distance: the flat scene intersects triangles transformed into the
// world in float, the two-level runtime the ray transformed into instance space in float.
constexpr float kRelativeT = 1e-4f;

// The flat baked scene traced by one tree, and the map from its triangle ids to (instance,
// triangle of the source) by the bake order.
struct FlatScene {
  anim::BakedScene baked;
  std::unique_ptr<tsah::CpuRuntime> runtime;
  std::vector<uint32_t> firstTriangle, firstVertex;  // per instance, in bake order

  FlatScene(const fs::path& scene, const anim::SceneSources& sources) : baked(anim::bakeScene(scene.string())) {
    const tsah::OptimizedTree tree = tsah::optimizeAnimation(baked.animation, tsah::test::smallTwoLevelOptions());
    const auto& a = baked.animation;
    runtime = std::make_unique<tsah::CpuRuntime>(tsah::flattenBvh(tree.bvh),
                                                 std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                                                 a.vertexCount(), tsah::CpuRuntime::Config(2));
    uint32_t t = 0, v = 0;
    for (const auto& i : sources.instances) {
      firstTriangle.push_back(t);
      firstVertex.push_back(v);
      t += sources.sourceOf(i).triangleCount();
      v += sources.sourceOf(i).vertexCount();
    }
  }
  std::pair<uint32_t, uint32_t> instanceOf(uint32_t tri) const {
    const auto it = std::upper_bound(firstTriangle.begin(), firstTriangle.end(), tri);
    const uint32_t instance = uint32_t(it - firstTriangle.begin()) - 1;
    return {instance, tri - firstTriangle[instance]};
  }
};

tsah::Vec3 vertexOf(const std::vector<float>& p, uint32_t v) { return {p[3 * v], p[3 * v + 1], p[3 * v + 2]}; }

bool containsPoint(const tsah::Aabb& b, const tsah::Vec3& p) {
  return p.x >= b.lo.x && p.x <= b.hi.x && p.y >= b.lo.y && p.y <= b.hi.y && p.z >= b.lo.z && p.z <= b.hi.z;
}

// The instance boxes at the scene frames a TLAS holds.
tsah::PrimitiveBoxes framesOf(const tsah::TwoLevelScene& scene, const tsah::TlasTree& tree) {
  tsah::PrimitiveBoxes boxes;
  boxes.frameCount = tree.frameCount;
  boxes.primCount = scene.instanceCount();
  for (uint32_t f = tree.firstFrame; f < tree.firstFrame + tree.frameCount; ++f)
    for (uint32_t i = 0; i < scene.instanceCount(); ++i) boxes.boxes.push_back(scene.instanceBoxes.at(f, i));
  return boxes;
}

// A scene file at 4 fps: the ground mesh 12 times on a circle of radius 20, each instance crossing
// to the opposite side by 8 s, after standing still until `still` seconds (0: moving from the start).
void writeCrossingScene(const fs::path& path, double still) {
  std::string instances;
  for (int i = 0; i < 12; ++i) {
    const double a = 0.5236 * i, x = 20.0 * std::cos(a), z = 20.0 * std::sin(a);
    const std::string from = std::to_string(x) + ", 0, " + std::to_string(z);
    const std::string hold = still > 0.0 ? R"(]}, {"time": )" + std::to_string(still) + R"(, "translate": [)" + from : "";
    instances += std::string(i ? ",\n" : "") + R"({"path": [{"time": 0, "translate": [)" + from + hold +
                 R"(]}, {"time": 8, "translate": [)" + std::to_string(-x) + ", 0, " + std::to_string(-z) + "]}]}";
  }
  tsah::test::writeText(path, R"({"fps": 4, "objects": [{"file": "ground.tanim", "instances": [)" + instances + "]}]}");
}

class TwoLevel : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = tsah::test::scratchDir();
    scenePath = tsah::test::writeTwoLevelScene(dir);
    scene = std::make_unique<tsah::TwoLevelScene>(tsah::loadTwoLevelScene(scenePath.string(), {}, tsah::test::smallTwoLevelOptions()));
  }
  fs::path dir, scenePath;
  std::unique_ptr<tsah::TwoLevelScene> scene;
};

TEST_F(TwoLevel, StructureOneBlasPerSourcePosesPerTimeMappingValidTrees) {
  ASSERT_EQ(scene->blases.size(), 2u);
  EXPECT_FALSE(scene->blases[0].animated);
  EXPECT_TRUE(scene->blases[1].animated);
  EXPECT_EQ(scene->blases[0].bvh.frameCount, 1u);
  EXPECT_EQ(scene->blases[1].bvh.frameCount, 3u);  // the source's own representative frames
  // Cloth instances: offsets 0, 1.5, 3 (loop) and 0 again: three poses, the first and last share one.
  ASSERT_EQ(scene->poses.size(), 3u);
  EXPECT_EQ(scene->instancePose[0], tsah::kInvalidIndex);
  EXPECT_EQ(scene->instancePose[3], scene->instancePose[6]);
  EXPECT_NE(scene->instancePose[3], scene->instancePose[4]);
  for (const tsah::Blas& b : scene->blases) {
    const anim::Animation& source = *scene->scene.sources[b.source];
    const tsah::PrimitiveBoxes rep = tsah::representativeBoxes(source, b.bvh.frameCount);
    EXPECT_EQ(tsah::validate(b.bvh, &rep), std::nullopt);
    EXPECT_GT(b.cost, 0.0);
  }
  // The TLAS trees cover the scene's frames, consecutive ones sharing their boundary frame.
  ASSERT_FALSE(scene->tlases.empty());
  EXPECT_EQ(scene->tlases.front().firstFrame, 0u);
  EXPECT_EQ(scene->tlases.back().firstFrame + scene->tlases.back().frameCount, scene->frameTimes.size());
  for (std::size_t t = 0; t < scene->tlases.size(); ++t) {
    const tsah::TlasTree& tree = scene->tlases[t];
    const tsah::PrimitiveBoxes boxes = framesOf(*scene, tree);
    EXPECT_EQ(tsah::validate(tree.bvh, &boxes), std::nullopt) << "TLAS " << t;
    EXPECT_EQ(tree.bvh.frameCount, tree.frameCount);
    if (t > 0) EXPECT_EQ(tree.firstFrame, scene->tlases[t - 1].firstFrame + scene->tlases[t - 1].frameCount - 1);
  }
  EXPECT_EQ(scene->frameTimes.size(), 25u);  // [0, 12] at 2 fps
  EXPECT_EQ(scene->tlasFrameCosts.size(), scene->frameTimes.size());
  EXPECT_GT(scene->tlasCost, 0.0);
  EXPECT_GT(scene->blasBytes(), 0u);
  EXPECT_GT(scene->tlasBytes(), 0u);
  EXPECT_GT(scene->memoryBytes(), scene->blasBytes() + scene->tlasBytes());
  // Each instance's TLAS box at frame f is its world box there.
  for (uint32_t f = 0; f < scene->frameTimes.size(); f += 6)
    for (uint32_t i = 0; i < scene->instanceCount(); ++i)
      EXPECT_EQ(scene->instanceBoxes.at(f, i).lo.x, tsah::instanceWorldBox(scene->scene, i, scene->frameTimes[f]).lo.x);
}

// Closest hits (and any hits) of the two-level runtime with BLAS in `layout`, TLAS refitted and
// TLAS rebuilt per frame, against the flat baked scene's bvh2 tree, at every third scene frame
// (the flat scene's keyframes: between them it interpolates world positions, the two-level scene
// source positions moved along the path). Rays run from random points around the scene to the
// centroid of a random triangle, so no ray is aimed at an edge. Hits agree when they name the same
// triangle of the same instance with t within kRelativeT; a different triangle at the same t
// (within the tolerance) is a tie between coincident surfaces, allowed for at most 2% of the hits.
void expectFlatHits(const tsah::TwoLevelScene& scene, const fs::path& scenePath, tsah::Layout layout,
                    tsah::TriangleForm poseTriangles = tsah::TriangleForm::Vertices) {
  const FlatScene flat(scenePath, scene.scene);
  tsah::TwoLevelRuntime runtime(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, layout, poseTriangles});
  tsah::TwoLevelRuntime rebuilt(scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Rebuild, layout, poseTriangles});
  if (layout != tsah::Layout::Bvh2)  // the poses in the form asked for, the static BLAS in the Woop form
    for (uint32_t i = 0; i < scene.instanceCount(); ++i) {
      const tsah::CpuRuntime& blas = runtime.blasOf(i);
      const tsah::TriangleForm form = blas.wide8() ? blas.wide8()->form() : blas.wide4()->form();
      const bool posed = scene.instancePose[i] != tsah::kInvalidIndex;
      EXPECT_EQ(form, posed ? poseTriangles : tsah::TriangleForm::Woop) << "instance " << i;
    }
  std::mt19937 rng(7);
  uint32_t rays = 0, hits = 0, ties = 0;
  for (uint32_t f = 0; f < scene.frameTimes.size(); f += 3) {
    const double t = scene.frameTimes[f];
    const std::vector<float> world = flat.baked.animation.positionsAt(t);
    flat.runtime->update(world);
    runtime.update(t);
    rebuilt.update(t);
    const tsah::Aabb bounds = flat.runtime->bounds();
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::uniform_int_distribution<uint32_t> pick(0, flat.baked.animation.triangleCount() - 1);
    for (int r = 0; r < 200; ++r, ++rays) {
      // From a random point around the scene at a random triangle's centroid (never an edge).
      const uint32_t* tri = flat.baked.animation.indices().data() + 3 * std::size_t(pick(rng));
      const tsah::Vec3 c = (vertexOf(world, tri[0]) + vertexOf(world, tri[1]) + vertexOf(world, tri[2])) * (1.0f / 3.0f);
      const tsah::Vec3 e = bounds.extent();
      const tsah::Vec3 o{bounds.lo.x + e.x * (2 * unit(rng) - 0.5f), bounds.lo.y + e.y * (2 * unit(rng) - 0.5f),
                         bounds.lo.z + e.z * (2 * unit(rng) - 0.5f)};
      tsah::Ray ray;
      ray.org = o;
      ray.dir = c - o;  // unnormalized: t = 1 at the centroid
      ray.tmin = 0.0f;
      ray.tmax = 1e30f;
      const tsah::Hit expected = flat.runtime->closestHit(ray);
      const tsah::TwoLevelHit got = runtime.closestHit(ray);
      const tsah::TwoLevelHit again = rebuilt.closestHit(ray);
      ASSERT_EQ(got.valid(), expected.valid()) << tsah::name(layout) << " frame " << f << " ray " << r;
      ASSERT_EQ(again.valid(), expected.valid());
      if (!expected.valid()) continue;
      ++hits;
      const float tolerance = kRelativeT * std::max(1.0f, expected.t);
      ASSERT_NEAR(got.t, expected.t, tolerance) << tsah::name(layout) << " frame " << f << " ray " << r;
      ASSERT_NEAR(again.t, got.t, tolerance);
      const auto [instance, prim] = flat.instanceOf(expected.tri);
      // A tie: two surfaces at the same distance (within the tolerance) may be reported either way.
      if (got.instance != instance || got.prim != prim) ++ties;
      // Any hit: a ray stopping halfway sees what the flat scene sees there.
      tsah::Ray shorter = ray;
      shorter.tmax = expected.t * 0.5f;
      EXPECT_EQ(runtime.anyHit(shorter), flat.runtime->anyHit(shorter));
      EXPECT_TRUE(runtime.anyHit(ray));
    }
  }
  EXPECT_GT(hits, rays / 2);
  EXPECT_LE(ties, hits / 50) << ties << " ties in " << hits << " hits";
}

TEST_F(TwoLevel, TheTopLevelOptimizedOverTimeCostsNoMoreThanSahOnTheFirstFrame) {
  // SAH0: the sweep-SAH TLAS of the first frame refitted to the others, collapsed the same way.
  tsah::BaselineConfig config = tsah::test::smallTwoLevelOptions().baselineConfig();
  const tsah::Bvh sah0 = tsah::buildSah0(scene->instanceBoxes, config);
  const double sah0Cost = tsah::temporalCost(tsah::frameCosts(sah0, config.objective.cost), tsah::test::smallTwoLevelOptions().objective.k);
  EXPECT_LE(scene->tlasCost, sah0Cost * (1 + 1e-9));
}

TEST_F(TwoLevel, ClosestHitsEqualTheFlatBakedScene) { expectFlatHits(*scene, scenePath, tsah::Layout::Bvh2); }

TEST_F(TwoLevel, WideBlasHitsEqualTheFlatBakedScene) {
  uint32_t traced = 0;
  for (const tsah::Layout layout : {tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
    if (!tsah::layoutSupported(layout)) continue;  // bvh8 needs AVX2
    for (const tsah::TriangleForm form : {tsah::TriangleForm::Vertices, tsah::TriangleForm::Woop})
      expectFlatHits(*scene, scenePath, layout, form);
    ++traced;
  }
  ASSERT_GT(traced, 0u);  // bvh4 runs on every x86-64 (SSE)
}

TEST_F(TwoLevel, TlasBoxesContainEveryInstanceAtEveryFrameAfterRefit) {
  const anim::BakedScene baked = anim::bakeScene(scenePath.string());
  const FlatScene flat(scenePath, scene->scene);
  tsah::TwoLevelRuntime runtime(*scene, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit});
  for (const double t : scene->frameTimes) {
    runtime.update(t);
    const std::vector<float> world = baked.animation.positionsAt(t);
    const std::vector<tsah::Aabb> leafBoxes = tsah::test::tlasLeafBoxes(runtime.tlas());
    for (uint32_t i = 0; i < scene->instanceCount(); ++i) {
      EXPECT_TRUE(leafBoxes[i].contains(runtime.instanceBoxes()[i])) << "t " << t << " instance " << i;
      const uint32_t count = scene->scene.sourceOf(scene->scene.instances[i]).vertexCount();
      for (uint32_t v = flat.firstVertex[i]; v < flat.firstVertex[i] + count; ++v)
        ASSERT_TRUE(containsPoint(leafBoxes[i], vertexOf(world, v))) << "t " << t << " instance " << i << " vertex " << v;
    }
    EXPECT_EQ(tsah::validateFlatBvh(runtime.tlas()), std::nullopt) << "t " << t;
  }
}

// Top-level trees per part of the scene's time (TlasOptions::trees): consecutive parts with
// boundaries at scene frames, each tree over the frames of its part; the runtime switches at the
// boundaries (a boundary frame takes the later tree), refits the part's tree and traces as the
// flat scene does. Equal parts here (no boundary search), so the boundaries are known.
TEST_F(TwoLevel, TlasTreesPerTimePartSwitchAtTheirBoundariesAndTraceAsTheFlatScene) {
  tsah::TlasOptions tlas;
  tlas.trees = 4;
  tlas.searchBoundaries = false;
  const tsah::TwoLevelScene parts =
      tsah::loadTwoLevelScene(scenePath.string(), {}, tsah::test::smallTwoLevelOptions(), tlas);
  ASSERT_EQ(parts.tlases.size(), 4u);
  ASSERT_EQ(parts.frameTimes.size(), 25u);  // 0..12 s at 2 fps: the parts hold frames 0-6, 6-12, 12-18, 18-24
  EXPECT_EQ(parts.tlases.front().range.start, parts.scene.start);
  EXPECT_EQ(parts.tlases.back().range.end, parts.scene.end);
  for (uint32_t s = 0; s < 4; ++s) {
    const tsah::TlasTree& tree = parts.tlases[s];
    EXPECT_EQ(tree.firstFrame, 6 * s);
    EXPECT_EQ(tree.frameCount, 7u);
    EXPECT_EQ(tree.bvh.frameCount, 7u);
    EXPECT_EQ(tree.info.timeStart, tree.range.start);
    EXPECT_EQ(tree.info.timeEnd, tree.range.end);
    if (s > 0) EXPECT_EQ(tree.range.start, parts.tlases[s - 1].range.end);
    const tsah::PrimitiveBoxes boxes = framesOf(parts, tree);
    EXPECT_EQ(tsah::validate(tree.bvh, &boxes), std::nullopt) << "TLAS " << s;
    // Each frame's cost is that of the tree used there, the later one on a boundary.
    const std::vector<double> costs = tsah::frameCosts(tree.bvh, parts.objective.cost);
    for (uint32_t f = tree.firstFrame; f < tree.firstFrame + tree.frameCount; ++f)
      if (parts.tlasAt(parts.frameTimes[f]) == s) EXPECT_DOUBLE_EQ(parts.tlasFrameCosts[f], costs[f - tree.firstFrame]);
  }
  EXPECT_EQ(parts.tlasAt(parts.frameTimes[5]), 0u);
  EXPECT_EQ(parts.tlasAt(parts.frameTimes[6]), 1u);
  EXPECT_EQ(parts.tlasAt(parts.frameTimes[24]), 3u);
  EXPECT_EQ(parts.tlasAt(-100.0), 0u);
  EXPECT_EQ(parts.tlasAt(100.0), 3u);

  tsah::TwoLevelRuntime runtime(parts, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit});
  for (uint32_t f = 0; f < parts.frameTimes.size(); ++f) {
    runtime.update(parts.frameTimes[f]);
    const uint32_t s = parts.tlasAt(parts.frameTimes[f]);
    EXPECT_EQ(runtime.tlas().triIndex, tsah::flattenBvh(parts.tlases[s].bvh).triIndex) << "frame " << f;
    const std::vector<tsah::Aabb> leafBoxes = tsah::test::tlasLeafBoxes(runtime.tlas());
    for (uint32_t i = 0; i < parts.instanceCount(); ++i)
      EXPECT_TRUE(leafBoxes[i].contains(runtime.instanceBoxes()[i])) << "frame " << f << " instance " << i;
  }
  expectFlatHits(parts, scenePath, tsah::Layout::Bvh2);
  expectFlatHits(parts, scenePath, tsah::Layout::Bvh4);
}

// Auto (TlasOptions::trees 0): one tree when it is within the budget of a TLAS rebuilt every
// frame; for instances that cross the whole scene (the ground mesh, 12 times, on paths through
// the middle) more parts, each doubling, until the budget is met or maxTrees reached.
TEST_F(TwoLevel, AutoTlasTreesStopAtTheBudget) {
  tsah::TlasOptions loose;
  loose.budget = 100.0;
  EXPECT_EQ(tsah::loadTwoLevelScene(scenePath.string(), {}, tsah::test::smallTwoLevelOptions(), loose).tlases.size(), 1u);

  writeCrossingScene(dir / "crossing.json", 0.0);
  tsah::TlasOptions one, automatic;
  one.trees = 1;
  const std::string crossing = (dir / "crossing.json").string();
  const tsah::TwoLevelScene single = tsah::loadTwoLevelScene(crossing, {}, tsah::test::smallTwoLevelOptions(), one);
  const tsah::TwoLevelScene parts = tsah::loadTwoLevelScene(crossing, {}, tsah::test::smallTwoLevelOptions(), automatic);
  const uint32_t trees = uint32_t(parts.tlases.size());
  EXPECT_GT(trees, 1u);
  EXPECT_EQ(trees & (trees - 1), 0u) << trees << " is not a power of 2";
  EXPECT_LT(tsah::temporalCost(parts.tlasFrameCosts, 0), tsah::temporalCost(single.tlasFrameCosts, 0));
  // Within the budget, or maxTrees reached.
  double rebuilt = 0.0;
  for (uint32_t f = 0; f < parts.frameTimes.size(); ++f) {
    std::vector<tsah::Aabb> frame;
    for (uint32_t i = 0; i < parts.instanceCount(); ++i) frame.push_back(parts.instanceBoxes.at(f, i));
    rebuilt += tsah::frameCosts(tsah::rebuildTlas(frame, parts.objective), parts.objective.cost)[0];
  }
  rebuilt /= double(parts.frameTimes.size());
  EXPECT_TRUE(tsah::temporalCost(parts.tlasFrameCosts, 0) <= automatic.budget * rebuilt ||
              trees == automatic.maxTrees);

  tsah::TlasOptions bad;
  bad.budget = 0.5;
  EXPECT_THROW(tsah::loadTwoLevelScene(scenePath.string(), {}, tsah::test::smallTwoLevelOptions(), bad), tsah::ConfigError);
  bad = {};
  bad.maxTrees = 0;
  EXPECT_THROW(bad.validate(), tsah::ConfigError);
}

// The parts' boundaries searched (TlasOptions::searchBoundaries, the default): instances that stand
// still for 6 s and cross the scene in the last 2 s. Equal parts put the still frames 4 to 6 s in
// the second part with the crossing; the search moves the boundary towards the crossing and the set
// costs less. The parts still touch, cover the scene and hold valid trees over their frames, and on
// the fixture's scene the search never costs more than equal parts.
TEST_F(TwoLevel, TlasPartBoundariesMoveToWhereTheInstancesMove) {
  writeCrossingScene(dir / "late.json", 6.0);
  const auto build = [&](const std::string& path, uint32_t trees, bool search) {
    tsah::TlasOptions tlas;
    tlas.trees = trees;
    tlas.searchBoundaries = search;
    return tsah::loadTwoLevelScene(path, {}, tsah::test::smallTwoLevelOptions(), tlas);
  };
  const std::string late = (dir / "late.json").string();
  const tsah::TwoLevelScene even = build(late, 2, false), searched = build(late, 2, true);
  ASSERT_EQ(even.frameTimes.size(), 33u);
  ASSERT_EQ(searched.tlases.size(), 2u);
  EXPECT_EQ(even.tlases[1].firstFrame, 16u);
  EXPECT_GT(searched.tlases[1].firstFrame, 16u);
  EXPECT_LT(tsah::temporalCost(searched.tlasFrameCosts, 0), tsah::temporalCost(even.tlasFrameCosts, 0));

  const tsah::TwoLevelScene fixtureEven = build(scenePath.string(), 4, false);
  const tsah::TwoLevelScene fixtureSearched = build(scenePath.string(), 4, true);
  EXPECT_LE(tsah::temporalCost(fixtureSearched.tlasFrameCosts, 0), tsah::temporalCost(fixtureEven.tlasFrameCosts, 0));
  for (const tsah::TwoLevelScene* parts : {&searched, &fixtureSearched}) {
    EXPECT_EQ(parts->tlases.front().range.start, parts->scene.start);
    EXPECT_EQ(parts->tlases.back().range.end, parts->scene.end);
    for (uint32_t s = 0; s < parts->tlases.size(); ++s) {
      const tsah::TlasTree& tree = parts->tlases[s];
      if (s > 0) {
        EXPECT_EQ(tree.range.start, parts->tlases[s - 1].range.end);
      }
      EXPECT_LT(tree.range.start, tree.range.end);
      EXPECT_EQ(tree.bvh.frameCount, tree.frameCount);
      const tsah::PrimitiveBoxes boxes = framesOf(*parts, tree);
      EXPECT_EQ(tsah::validate(tree.bvh, &boxes), std::nullopt) << "TLAS " << s;
      const std::vector<double> costs = tsah::frameCosts(tree.bvh, parts->objective.cost);
      for (uint32_t f = tree.firstFrame; f < tree.firstFrame + tree.frameCount; ++f) {
        if (parts->tlasAt(parts->frameTimes[f]) == s) {
          EXPECT_DOUBLE_EQ(parts->tlasFrameCosts[f], costs[f - tree.firstFrame]);
        }
      }
    }
  }
  expectFlatHits(fixtureSearched, scenePath, tsah::Layout::Bvh2);
}

TEST_F(TwoLevel, InstancesOfOneBlasWithDifferentOffsetsTraceTheirOwnPoses) {
  tsah::TwoLevelRuntime runtime(*scene);
  const anim::SceneSources& s = scene->scene;
  const anim::Animation& wave = *s.sources[1];
  const double t = 2.0;
  runtime.update(t);
  // Instances 3 (offset 0) and 4 (offset 1.5) share the cloth BLAS but show it at 2.0 and 0.5.
  EXPECT_NE(&runtime.blasOf(3), &runtime.blasOf(4));
  EXPECT_EQ(&runtime.blasOf(3), &runtime.blasOf(6));
  for (const uint32_t instance : {3u, 4u}) {
    const anim::SceneSourceInstance& i = s.instances[instance];
    std::vector<float> p = wave.positionsAt(i.localTime(t, wave));
    anim::transformPoints(i.worldAt(t), p.data(), wave.vertexCount());
    uint32_t found = 0;
    for (uint32_t tri = 0; tri < wave.triangleCount(); tri += 17) {
      const uint32_t* v = wave.indices().data() + 3 * tri;
      const tsah::Vec3 c = (vertexOf(p, v[0]) + vertexOf(p, v[1]) + vertexOf(p, v[2])) * (1.0f / 3.0f);
      tsah::Ray ray;
      ray.org = c + tsah::Vec3{0.0f, 20.0f, 0.0f};
      ray.dir = {0.0f, -1.0f, 0.0f};
      ray.tmin = 0.0f;
      ray.tmax = 40.0f;
      const tsah::TwoLevelHit hit = runtime.closestHit(ray);
      ASSERT_TRUE(hit.valid());
      // Nothing of this instance's own pose lies above its own centroid further than the hit.
      if (hit.instance == instance && hit.prim == tri) {
        EXPECT_NEAR(hit.t, 20.0f, 1e-3f);
        ++found;
      }
    }
    EXPECT_GT(found, 0u) << "instance " << instance;
  }
  // The two poses differ: the same triangle sits elsewhere in each instance's own space.
  EXPECT_NE(runtime.blasOf(3).bounds().lo.y, runtime.blasOf(4).bounds().lo.y);
}

TEST_F(TwoLevel, AFrameWithOnlyRigidMotionRefitsNoBlas) {
  tsah::TwoLevelRuntime runtime(*scene);
  EXPECT_EQ(runtime.blasRefits(), 1u + 3u);  // the static BLAS once, the three poses at the first frame
  runtime.update(2.0);
  EXPECT_EQ(runtime.lastUpdateBlasRefits(), 3u);  // the three poses move at 2.0
  runtime.update(2.0);
  EXPECT_EQ(runtime.lastUpdateBlasRefits(), 0u);  // nothing changed
  // After 9.5 the source's last frame holds for offsets 0 and 1.5; the looping pose keeps moving.
  runtime.update(9.5);
  const uint64_t before = runtime.blasRefits();
  const tsah::Aabb pathBefore = runtime.instanceBoxes()[2];
  runtime.update(10.0);
  EXPECT_EQ(runtime.lastUpdateBlasRefits(), 1u);  // the looping pose only
  EXPECT_EQ(runtime.blasRefits(), before + 1);
  EXPECT_NE(runtime.instanceBoxes()[2].lo.x, pathBefore.lo.x);  // the keyed instance did move
}

TEST(TwoLevelRigid, OnlyPathsAndHeldPosesRefitNothing) {
  const fs::path dir = tsah::test::scratchDir();
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeRigidPathScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  tsah::TwoLevelRuntime runtime(s);
  runtime.update(3.0);
  EXPECT_EQ(runtime.lastUpdateBlasRefits(), 2u);
  runtime.update(5.0);  // both poses reach their last frame (local time 4)
  EXPECT_EQ(runtime.lastUpdateBlasRefits(), 2u);
  for (const double t : {6.0, 6.25, 7.0, 8.0}) {  // and hold it while the path moves on
    runtime.update(t);
    EXPECT_EQ(runtime.lastUpdateBlasRefits(), 0u) << "t " << t;
  }
}

TEST(TwoLevelRigid, AnInstanceFlattenedByItsPathIsNeverHitThenAndTracesAgainAfter) {
  const fs::path dir = tsah::test::scratchDir();
  // At t = 1 the instance is flat (a singular world transform).
  const tsah::TwoLevelScene s =
      tsah::loadTwoLevelScene(tsah::test::writeFlattenedTriangleScene(dir).string(), {}, tsah::test::smallTwoLevelOptions());
  tsah::Ray across;  // along x through (x, 1/3, 1/3)
  across.org = {-2.0f, 1.0f / 3.0f, 1.0f / 3.0f};
  across.dir = {1.0f, 0.0f, 0.0f};
  across.tmin = 0.0f;
  across.tmax = 10.0f;
  // bvh4 / bvh8: the wide TLAS of a single instance is a leaf root.
  for (const tsah::Layout layout : {tsah::Layout::Bvh2, tsah::Layout::Bvh4, tsah::Layout::Bvh8}) {
    if (!tsah::layoutSupported(layout)) continue;  // bvh8 needs AVX2
    tsah::TwoLevelRuntime runtime(s, {1, tsah::TwoLevelRuntime::TlasUpdate::Refit, layout});
    runtime.update(1.0);
    EXPECT_FALSE(runtime.closestHit(across).valid()) << tsah::name(layout);
    EXPECT_FALSE(runtime.anyHit(across)) << tsah::name(layout);
    runtime.update(2.0);  // mirrored: (-1,0,0) (0,1,0) (0,0,1), crossed at x = -1/3
    const tsah::TwoLevelHit hit = runtime.closestHit(across);
    ASSERT_TRUE(hit.valid()) << tsah::name(layout);
    EXPECT_EQ(hit.instance, 0u);
    EXPECT_EQ(hit.prim, 0u);
    EXPECT_NEAR(hit.t, 2.0f - 1.0f / 3.0f, 1e-5f) << tsah::name(layout);
    EXPECT_TRUE(runtime.anyHit(across, tsah::AnyHitOrder::TreeOrder)) << tsah::name(layout);
  }
}

TEST(TwoLevelAffine, InverseOfAMirroredScaledRotation) {
  const anim::Matrix4 m = anim::multiply(anim::trsMatrix({1, 2, 3}, {10, 20, 30}, {2, -0.5, 3}), anim::identityMatrix());
  const anim::Matrix4 product = anim::multiply(m, tsah::inverseAffine(m));
  for (int i = 0; i < 16; ++i) EXPECT_NEAR(product[i], anim::identityMatrix()[i], 1e-12) << i;
  anim::Matrix4 singular = anim::identityMatrix();
  singular[5] = 0.0;
  EXPECT_THROW(tsah::inverseAffine(singular), tsah::DataError);
}

TEST(TwoLevelAffine, RaysMovedIntoInstanceSpaceOnTheHostAreRayInInstancesBits) {
  // The CPU runtime moves rays with rayInInstanceHost (SSE on x86-64); the GPU with rayInInstance.
  // Their hits must agree, so the two must give the same bits: random maps (mirrored, scales from
  // 1e-3 to 1e3, translations to 1e4) and rays.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  const auto bits = [](float x) {
    uint32_t b;
    std::memcpy(&b, &x, 4);
    return b;
  };
  for (int i = 0; i < 20000; ++i) {
    tsah::Affine3x4 map;
    const float scale = std::pow(10.0f, 3.0f * unit(rng));
    for (int k = 0; k < 12; ++k) map.m[k] = (k % 4 == 3 ? 1e4f : scale) * unit(rng);
    const tsah::Ray ray{{100 * unit(rng), 100 * unit(rng), 100 * unit(rng)}, std::abs(unit(rng)),
                        {unit(rng), unit(rng), unit(rng)}, 50.0f};
    const float tmax = 10.0f * std::abs(unit(rng));
    const tsah::Ray a = tsah::rayInInstance(map, ray, tmax), b = tsah::rayInInstanceHost(map, ray, tmax);
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(bits(a.org[k]), bits(b.org[k])) << i << " org " << k;
      ASSERT_EQ(bits(a.dir[k]), bits(b.dir[k])) << i << " dir " << k;
    }
    ASSERT_EQ(bits(a.tmin), bits(b.tmin));
    ASSERT_EQ(bits(a.tmax), bits(b.tmax));
  }
}

TEST_F(TwoLevel, AStructureWithoutInstancesIsRefused) {
  anim::SceneSources empty = anim::loadSceneSources(scenePath.string());
  empty.instances.clear();
  EXPECT_THROW(tsah::buildTwoLevelScene(std::move(empty), tsah::test::smallTwoLevelOptions()), tsah::DataError);
}

TEST(TwoLevelOptions, OnlyTSahTrees) {
  const fs::path dir = tsah::test::scratchDir();
  writeText(dir / "tri.obj", "v 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n");
  writeText(dir / "s.json", R"({"objects": [{"file": "tri.obj"}]})");
  tsah::TreeOptions options;
  options.method = tsah::Method::Sah0;
  EXPECT_THROW(tsah::loadTwoLevelScene((dir / "s.json").string(), {}, options), tsah::ConfigError);
  options.method = tsah::Method::TSah;
  const tsah::TwoLevelScene one = tsah::loadTwoLevelScene((dir / "s.json").string(), {}, options);
  tsah::TwoLevelRuntime runtime(one);
  tsah::Ray ray;
  ray.org = {0.0f, 0.0f, 0.0f};
  ray.dir = {1.0f, 1.0f, 1.0f};
  ray.tmin = 0.0f;
  ray.tmax = 10.0f;
  const tsah::TwoLevelHit hit = runtime.closestHit(ray);
  ASSERT_TRUE(hit.valid());
  EXPECT_EQ(hit.instance, 0u);
  EXPECT_EQ(hit.prim, 0u);
  EXPECT_NEAR(hit.t, 1.0f / 3.0f, 1e-6f);
}

}  // namespace
