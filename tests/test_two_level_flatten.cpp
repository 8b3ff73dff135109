// Objects flattened into their parent level (anim::flattenObjects, docs/two-level.md): the merged
// source traced by the two-level runtime gives the flat baked scene's hits, and --structure auto's
// cost estimate (tsah::chooseObjectStructure) flattens overlapping instances and keeps spread-out ones.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "anim/scene.hpp"
#include "anim/tanim.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/scene/structure_choice.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "test_support.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

using tsah::test::writeText;

// `count` instances of `file`, one JSON instance each from `instance(i)`.
std::string instances(uint32_t count, const std::function<std::string(uint32_t)>& instance) {
  std::string out;
  for (uint32_t i = 0; i < count; ++i) out += (i ? ",\n" : "") + instance(i);
  return out;
}

// Object 0, "ground": a static mesh in three spread-out instances (kept instanced). Object 1,
// "crowd": 12 overlapping instances of an animated wave, each with its own time offset, turn and
// keyed path across the others (flattened). Object 2, "statue": a static mesh shown once.
fs::path writeMixedScene(const fs::path& dir) {
  tsah::test::writeTwoLevelScene(dir);  // wave.tanim (animated, keyframes 0..8) and ground.tanim (static)
  writeText(dir / "statue.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n");
  const std::string crowd = instances(12, [](uint32_t i) {
    const double a = 30.0 * i, x = 0.3 * std::cos(i), z = 0.3 * std::sin(i);
    return R"({"time": {"offset": )" + std::to_string(0.5 * i) + R"(, "outside": "loop"}, "path": [{"time": 0, "translate": [)" +
           std::to_string(x) + ", 2, " + std::to_string(z) + R"(], "rotate": [0, )" + std::to_string(a) +
           R"(, 0]}, {"time": 6, "translate": [)" + std::to_string(-z) + ", 2.5, " + std::to_string(x) +
           R"(], "rotate": [0, )" + std::to_string(a + 40) + R"(, 0]}]})";
  });
  writeText(dir / "mixed.json", R"({"fps": 2, "objects": [
    {"name": "ground", "file": "ground.tanim", "instances": [
      {"transform": {"translate": [0, -1, 0], "scale": [3, 0.5, 2]}},
      {"transform": {"translate": [9, -1, 0], "rotate": [0, 90, 0]}},
      {"transform": {"translate": [-9, -1, 0], "scale": [-1, 1, 1]}}]},
    {"name": "crowd", "file": "wave.tanim", "instances": [)" + crowd + R"(]},
    {"name": "statue", "file": "statue.obj", "transform": {"translate": [4, 0, 4], "rotate": [10, 20, 30]}}]})");
  return dir / "mixed.json";
}

tsah::Vec3 vertexOf(const std::vector<float>& p, uint32_t v) { return {p[3 * v], p[3 * v + 1], p[3 * v + 2]}; }

TEST(FlattenObjects, OneMergedSourceShownByOneInstanceMappedBackToTheBake) {
  const fs::path scene = writeMixedScene(tsah::test::scratchDir());
  const anim::SceneSources whole = anim::loadSceneSources(scene.string());
  const anim::SceneSources flat = anim::flattenObjects(whole, {1, 2});
  EXPECT_EQ(flat.flattenedObjects, (std::vector<uint32_t>{1, 2}));
  // ground's three instances, then the merged one; wave.tanim and statue.obj are shown by nobody else.
  ASSERT_EQ(flat.instances.size(), 4u);
  ASSERT_EQ(flat.sources.size(), 2u);
  const anim::Animation& merged = *flat.sources[1];
  EXPECT_EQ(flat.instances[3].source, 1u);
  EXPECT_FALSE(flat.instances[3].keyed());
  EXPECT_EQ(merged.keyframeCount(), flat.frameCount);  // the crowd moves: keyframes at the scene's frames
  EXPECT_EQ(merged.triangleCount(), 12 * whole.sources[1]->triangleCount() + 4);
  // The merged source at a scene frame is the bake's positions of those instances, in bake order.
  const anim::BakedScene baked = anim::bakeScene(scene.string());
  const double t = flat.frameTimes()[5];
  const std::vector<float> world = baked.animation.positionsAt(t);
  const std::vector<float> mine = merged.positionsAt(flat.instances[3].localTime(t, merged));
  for (uint32_t prim = 0; prim < merged.triangleCount(); prim += 7) {
    const uint32_t tri = flat.bakedTriangle(3, prim);
    for (int c = 0; c < 3; ++c) {
      const tsah::Vec3 a = vertexOf(mine, merged.indices()[3 * prim + c]);
      const tsah::Vec3 b = vertexOf(world, baked.animation.indices()[3 * std::size_t(tri) + c]);
      EXPECT_FLOAT_EQ(a.x, b.x) << prim;
      EXPECT_FLOAT_EQ(a.y, b.y) << prim;
      EXPECT_FLOAT_EQ(a.z, b.z) << prim;
    }
  }
  EXPECT_EQ(flat.bakedTriangle(1, 5), whole.bakedTriangle(1, 5));
  EXPECT_EQ(flat.runOf(3, 0).originalInstance, 3u);  // the crowd's first instance
  EXPECT_EQ(flat.runOf(3, 0).object, 1u);
  EXPECT_EQ(flat.runOf(3, merged.triangleCount() - 1).originalInstance, 15u);  // the statue
  EXPECT_EQ(flat.runOf(3, merged.triangleCount() - 1).object, 2u);
  // Only static objects flattened: one keyframe.
  EXPECT_EQ(anim::flattenObjects(whole, {0, 2}).sources.back()->keyframeCount(), 1u);
  EXPECT_THROW(anim::flattenObjects(whole, {2, 1}), tsah::ConfigError);
  EXPECT_THROW(anim::flattenObjects(whole, {3}), tsah::ConfigError);
  EXPECT_THROW(anim::flattenObjects(flat, {0}), tsah::ConfigError);
  EXPECT_THROW((void)flat.bakedTriangle(3, merged.triangleCount()), tsah::ConfigError);
}

// Closest hits of the two-level runtime over the flattened scene name the flat baked tree's
// triangle (mapped back by bakedTriangle) at every other scene frame, with t within 1e-4.
TEST(FlattenObjects, TwoLevelHitsOfAFlattenedSceneEqualTheFlatBakedScene) {
  const fs::path scene = writeMixedScene(tsah::test::scratchDir());
  const tsah::TwoLevelScene twoLevel =
      tsah::buildTwoLevelScene(anim::flattenObjects(anim::loadSceneSources(scene.string()), {1, 2}),
                               tsah::test::smallTwoLevelOptions());
  ASSERT_EQ(twoLevel.instanceCount(), 4u);
  const anim::BakedScene baked = anim::bakeScene(scene.string());
  const tsah::OptimizedTree tree = tsah::optimizeAnimation(baked.animation, tsah::test::smallTwoLevelOptions());
  const anim::Animation& a = baked.animation;
  tsah::CpuRuntime flat(tsah::flattenBvh(tree.bvh), std::vector<uint32_t>(a.indices().begin(), a.indices().end()),
                        a.vertexCount(), tsah::CpuRuntime::Config(2));
  tsah::TwoLevelRuntime runtime(twoLevel, {2, tsah::TwoLevelRuntime::TlasUpdate::Refit, tsah::Layout::Bvh2});
  std::mt19937 rng(11);
  uint32_t hits = 0, ties = 0, rays = 0;
  for (uint32_t f = 0; f < twoLevel.frameTimes.size(); f += 2) {
    const double t = twoLevel.frameTimes[f];
    const std::vector<float> world = a.positionsAt(t);
    flat.update(world);
    runtime.update(t);
    const tsah::Aabb bounds = flat.bounds();
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::uniform_int_distribution<uint32_t> pick(0, a.triangleCount() - 1);
    for (int r = 0; r < 150; ++r, ++rays) {
      const uint32_t* tri = a.indices().data() + 3 * std::size_t(pick(rng));
      const tsah::Vec3 c = (vertexOf(world, tri[0]) + vertexOf(world, tri[1]) + vertexOf(world, tri[2])) * (1.0f / 3.0f);
      const tsah::Vec3 e = bounds.extent();
      tsah::Ray ray;
      ray.org = {bounds.lo.x + e.x * (2 * unit(rng) - 0.5f), bounds.lo.y + e.y * (2 * unit(rng) - 0.5f),
                 bounds.lo.z + e.z * (2 * unit(rng) - 0.5f)};
      ray.dir = c - ray.org;
      ray.tmin = 0.0f;
      ray.tmax = 1e30f;
      const tsah::Hit expected = flat.closestHit(ray);
      const tsah::TwoLevelHit got = runtime.closestHit(ray);
      ASSERT_EQ(got.valid(), expected.valid()) << "frame " << f << " ray " << r;
      if (!expected.valid()) continue;
      ++hits;
      ASSERT_NEAR(got.t, expected.t, 1e-4f * std::max(1.0f, expected.t)) << "frame " << f << " ray " << r;
      if (twoLevel.scene.bakedTriangle(got.instance, got.prim) != expected.tri) ++ties;
      tsah::Ray shorter = ray;
      shorter.tmax = expected.t * 0.5f;
      EXPECT_EQ(runtime.anyHit(shorter), flat.anyHit(shorter));
    }
  }
  EXPECT_GT(hits, rays / 2);
  EXPECT_LE(ties, hits / 50) << ties << " ties in " << hits << " hits";
}

// 16 instances of an animated wave of 3,000 triangles, each turned and phased: crowded
// (overlapping) or spread out on a grid far apart; and a ground shown once. With `spreadToo`, a
// third object: 16 more instances of the wave spread out beside them.
fs::path writeManyInstances(const fs::path& dir, bool crowded, bool spreadToo = false) {
  tsah::test::writeTwoLevelScene(dir);
  anim::saveTanim(tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 3000, 9, 3), (dir / "big.tanim").string());
  const auto many = [](bool close, double shift) {
    return instances(16, [close, shift](uint32_t i) {
      const double spacing = close ? 0.25 : 12.0;
      const double x = shift + spacing * (i % 4), z = spacing * (i / 4);
      return R"({"time": {"offset": )" + std::to_string(0.37 * i) + R"(, "outside": "loop"}, "transform": {"translate": [)" +
             std::to_string(x) + ", 0, " + std::to_string(z) + R"(], "rotate": [0, )" + std::to_string(23.0 * i) + R"(, 0]}})";
    });
  };
  const std::string strollers =
      spreadToo ? R"(, {"name": "strollers", "file": "big.tanim", "instances": [)" + many(false, 60.0) + "]}" : "";
  writeText(dir / "many.json", R"({"fps": 2, "objects": [
    {"name": "ground", "file": "ground.tanim", "instances": [{"transform": {"translate": [0, -2, 0], "scale": [20, 1, 20]}}]},
    {"name": "walkers", "file": "big.tanim", "instances": [)" + many(crowded, 0.0) + "]}" + strollers + "]}");
  return dir / "many.json";
}

TEST(StructureChoice, OverlappingInstancesAreFlattenedByTheirCost) {
  const anim::SceneSources scene = anim::loadSceneSources(writeManyInstances(tsah::test::scratchDir(), true).string());
  const tsah::StructureChoice choice = tsah::chooseObjectStructure(scene);
  ASSERT_EQ(choice.objects.size(), 2u);
  const tsah::ObjectStructureChoice& walkers = choice.objects[1];
  EXPECT_TRUE(walkers.moves);
  EXPECT_GT(walkers.instancedCost, 0.0);
  EXPECT_LT(walkers.flattenedCost, 0.9 * walkers.instancedCost) << walkers.reason;
  EXPECT_TRUE(walkers.flatten) << walkers.reason;
  EXPECT_EQ(walkers.reason.rfind("flattened: ", 0), 0u) << walkers.reason;
  // The static ground is not estimated alone once a moving object is flattened. The walkers'
  // flattened source lies on it, so the whole scene weighed as one tree costs less than the two
  // levels: every object is flattened (a flat tree).
  EXPECT_GT(choice.decidedCost, 0.0);
  EXPECT_GT(choice.wholeFlattenedCost, 0.0);
  EXPECT_LE(choice.wholeFlattenedCost, choice.decidedCost);
  EXPECT_EQ(choice.objects[0].reason.rfind("flattened with the whole scene: ", 0), 0u) << choice.objects[0].reason;
  EXPECT_EQ(choice.flattenedObjects, (std::vector<uint32_t>{0, 1}));
  EXPECT_TRUE(choice.allFlattened());
}

TEST(StructureChoice, TheWholeSceneIsWeighedWithinItsBounds) {
  const anim::SceneSources scene = anim::loadSceneSources(writeManyInstances(tsah::test::scratchDir(), true).string());
  uint64_t structure = 0, walkers = 0;
  for (const auto& source : scene.sources) structure += source->triangleCount();
  for (const anim::SceneSourceInstance& i : scene.instances)
    if (i.object == 1) walkers += scene.sourceOf(i).triangleCount();
  const uint64_t whole = walkers + scene.sources[scene.instances[0].source]->triangleCount();
  // The walkers' copies fit the bound, the whole scene's do not.
  tsah::StructureChoiceOptions options;
  options.memoryFactor = (double(walkers) + 0.5 * double(whole - walkers)) / double(structure);
  const tsah::StructureChoice choice = tsah::chooseObjectStructure(scene, options);
  EXPECT_TRUE(choice.objects[1].flatten) << choice.objects[1].reason;
  EXPECT_FALSE(choice.objects[0].flatten) << choice.objects[0].reason;
  EXPECT_LT(choice.decidedCost, 0.0);
  EXPECT_LT(choice.wholeFlattenedCost, 0.0);
  EXPECT_EQ(choice.flattenedObjects, (std::vector<uint32_t>{1}));
  // The kept ground's triangles past wholeSceneFactor times the walkers': not weighed either.
  tsah::StructureChoiceOptions small;
  small.wholeSceneFactor = 0.5 * double(whole - walkers) / double(walkers);
  const tsah::StructureChoice kept = tsah::chooseObjectStructure(scene, small);
  EXPECT_FALSE(kept.objects[0].flatten) << kept.objects[0].reason;
  EXPECT_LT(kept.decidedCost, 0.0);
  EXPECT_EQ(kept.flattenedObjects, (std::vector<uint32_t>{1}));
}

TEST(StructureChoice, AKeptMovingObjectKeepsTheTwoLevels) {
  // The crowded walkers are flattened, the spread-out strollers (moving too) stay instances: one
  // tree would refit each of their copies, so the whole scene is not weighed.
  const anim::SceneSources scene =
      anim::loadSceneSources(writeManyInstances(tsah::test::scratchDir(), true, true).string());
  tsah::StructureChoiceOptions options;
  options.memoryFactor = 100.0;
  options.wholeSceneFactor = 100.0;
  const tsah::StructureChoice choice = tsah::chooseObjectStructure(scene, options);
  ASSERT_EQ(choice.objects.size(), 3u);
  EXPECT_TRUE(choice.objects[1].flatten) << choice.objects[1].reason;
  EXPECT_FALSE(choice.objects[2].flatten) << choice.objects[2].reason;
  EXPECT_TRUE(choice.objects[2].moves);
  EXPECT_FALSE(choice.objects[0].flatten) << choice.objects[0].reason;
  EXPECT_LT(choice.decidedCost, 0.0);
  EXPECT_EQ(choice.flattenedObjects, (std::vector<uint32_t>{1}));
}

TEST(StructureChoice, SpreadOutInstancesStayInstances) {
  const anim::SceneSources scene = anim::loadSceneSources(writeManyInstances(tsah::test::scratchDir(), false).string());
  const tsah::StructureChoice choice = tsah::chooseObjectStructure(scene);
  const tsah::ObjectStructureChoice& walkers = choice.objects[1];
  EXPECT_GT(walkers.flattenedCost, 0.9 * walkers.instancedCost);
  EXPECT_FALSE(walkers.flatten) << walkers.reason;
  // No moving object is flattened: the ground, one instance without a path, is.
  EXPECT_TRUE(choice.objects[0].flatten) << choice.objects[0].reason;
  EXPECT_EQ(choice.flattenedObjects, (std::vector<uint32_t>{0}));
}

TEST(StructureChoice, TheMemoryBoundKeepsInstancesWhateverTheCost) {
  const anim::SceneSources scene = anim::loadSceneSources(writeManyInstances(tsah::test::scratchDir(), true).string());
  tsah::StructureChoiceOptions options;
  options.memoryFactor = 8.0;  // 16 copies of the wave against the wave and the ground once: more than 8x
  const tsah::StructureChoice choice = tsah::chooseObjectStructure(scene, options);
  EXPECT_FALSE(choice.objects[1].flatten);
  EXPECT_NE(choice.objects[1].reason.find("memory bound"), std::string::npos) << choice.objects[1].reason;
}

TEST(StructureChoice, OneInstanceObjectsAllFlattenedMakeAFlatTree) {
  const fs::path dir = tsah::test::scratchDir();
  tsah::test::writeTwoLevelScene(dir);
  writeText(dir / "two.json", R"({"fps": 2, "objects": [{"file": "ground.tanim"},
    {"file": "ground.tanim", "transform": {"translate": [5, 0, 0]}}]})");
  const tsah::StructureChoice choice = tsah::chooseObjectStructure(anim::loadSceneSources((dir / "two.json").string()));
  EXPECT_TRUE(choice.allFlattened());
}

}  // namespace
