// The phases of a build that run on all cores give the same result for any thread count
// (tbb::global_control): the binned SAH builder (parallel binning, stable partition, concurrent
// subtree copies), the representative frames' triangle boxes, a scene's sources loaded and
// subdivided concurrently (errors as if loaded one by one), and the whole two-level structure.
#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <cstring>
#include <string>
#include <vector>

#include "anim/generators.hpp"
#include "anim/scene.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/scene/two_level.hpp"
#include "test_support.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

constexpr int kThreadCounts[] = {1, 2, 3, 8};

// f() with at most `threads` TBB threads.
template <typename F>
auto withThreads(int threads, F&& f) {
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  return f();
}

bool sameBoxes(const std::vector<tsah::Aabb>& a, const std::vector<tsah::Aabb>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(tsah::Aabb)) == 0;
}

// Structure the builder documents beyond tsah::validate: root 0, adjacent children.
void expectBuilderLayout(const tsah::Bvh& bvh, const std::vector<tsah::Aabb>& boxes) {
  tsah::PrimitiveBoxes prims;
  prims.frameCount = 1;
  prims.primCount = uint32_t(boxes.size());
  prims.boxes = boxes;
  const auto problem = tsah::validate(bvh, &prims);
  ASSERT_FALSE(problem) << *problem;
  EXPECT_EQ(bvh.root, 0u);
  for (const tsah::BvhNode& n : bvh.nodes)
    if (!n.isLeaf()) EXPECT_EQ(n.right, n.left + 1);
}

TEST(ParallelBinnedBuild, SameTreeForEveryThreadCount) {
  // Many top levels (threshold 256 of 40,000 triangles) and, in the second input, 6,000 boxes on
  // four centroids: the top levels halve ranges no bin can split, which depends on the order the
  // partition leaves.
  const auto scattered = tsah::test::keyframeBoxes(tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 40000, 2), 1);
  std::vector<tsah::Aabb> clustered;
  for (uint32_t i = 0; i < 6000; ++i) {
    tsah::Aabb b;
    const float c = float(i % 4);
    b.extend(tsah::Vec3{c, c, c});
    b.extend(tsah::Vec3{c + 0.5f, c + float(i % 7) * 0.01f + 0.5f, c + 0.5f});
    clustered.push_back(b);
  }
  for (const std::vector<tsah::Aabb>* boxes : std::vector<const std::vector<tsah::Aabb>*>{&scattered, &clustered}) {
    tsah::BinnedSahBuilder::Config c;
    c.maxLeafSize = 1;
    c.parallelThreshold = 256;
    const tsah::Bvh reference = withThreads(1, [&] { return tsah::BinnedSahBuilder(c).build(*boxes); });
    expectBuilderLayout(reference, *boxes);
    for (int threads : kThreadCounts) {
      const tsah::Bvh tree = withThreads(threads, [&] { return tsah::BinnedSahBuilder(c).build(*boxes); });
      EXPECT_TRUE(tsah::test::identicalTree(reference, tree)) << threads << " threads";
    }
  }
}

TEST(ParallelBinnedBuild, SahCostOfTheSequentialBuilder) {
  // The same split decisions as one task over the whole range (no parallel pass): the same cost.
  for (auto kind : {anim::GeneratorKind::Explode, anim::GeneratorKind::Wave}) {
    const auto boxes = tsah::test::keyframeBoxes(tsah::test::generatedAnimation(kind, 30000, 2), 0);
    tsah::BinnedSahBuilder::Config c;
    c.maxLeafSize = 1;
    c.parallelThreshold = 300;
    const tsah::Bvh parallel = tsah::BinnedSahBuilder(c).build(boxes);
    c.parallelThreshold = 1u << 30;
    const tsah::Bvh sequential = tsah::BinnedSahBuilder(c).build(boxes);
    expectBuilderLayout(parallel, boxes);
    EXPECT_EQ(parallel.nodes.size(), sequential.nodes.size()) << anim::generatorName(kind);
    EXPECT_DOUBLE_EQ(tsah::frameCost(parallel, 0), tsah::frameCost(sequential, 0)) << anim::generatorName(kind);
  }
}

TEST(ParallelBuild, RepresentativeBoxesInChunksEqualTheTrianglesBoxes) {
  // More triangles than one chunk (65,536), so chunk edges are crossed.
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 140000, 4);
  const tsah::PrimitiveBoxes reference = withThreads(1, [&] { return tsah::representativeBoxes(a, 3); });
  const std::vector<double> times = a.uniformTimes(3);
  ASSERT_EQ(reference.frameCount, 3u);
  for (uint32_t f = 0; f < 3; ++f) {
    std::vector<tsah::Aabb> direct(a.triangleCount());
    tsah::triangleBoxes(a.indices(), a.positionsAt(times[f]), direct);
    const auto frame = reference.frame(f);
    EXPECT_TRUE(sameBoxes(direct, std::vector<tsah::Aabb>(frame.begin(), frame.end()))) << "frame " << f;
  }
  for (int threads : kThreadCounts)
    EXPECT_TRUE(sameBoxes(reference.boxes, withThreads(threads, [&] { return tsah::representativeBoxes(a, 3); }).boxes))
        << threads << " threads";
}

// A closed tetrahedron (subdivides) and a mesh with an edge of three triangles (does not).
void writeMeshes(const fs::path& dir) {
  tsah::test::writeText(dir / "tetra.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
  tsah::test::writeText(dir / "fin.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 0 -1 0\nf 1 2 3\nf 1 2 4\nf 1 2 5\n");
}

TEST(ParallelSceneLoad, SourcesDoNotDependOnTheThreadCount) {
  const fs::path dir = tsah::test::scratchDir();
  writeMeshes(dir);
  tsah::test::writeText(dir / "s.json", R"({"objects": [
    {"name": "a", "file": "tetra.obj", "subdivide": 3},
    {"name": "b", "file": "tetra.obj", "subdivide": 1, "transform": {"translate": [3, 0, 0]}},
    {"name": "c", "file": "tetra.obj", "subdivide": 3, "transform": {"translate": [6, 0, 0]}},
    {"name": "d", "file": "fin.obj"}]})");
  const std::string scene = (dir / "s.json").string();
  const anim::SceneSources reference = withThreads(1, [&] { return anim::loadSceneSources(scene); });
  ASSERT_EQ(reference.sources.size(), 3u);  // a and c share one source
  EXPECT_EQ(reference.objectSource, (std::vector<uint32_t>{0, 1, 0, 2}));
  EXPECT_EQ(reference.sources[0]->triangleCount(), 4u * 64u);
  EXPECT_EQ(reference.sources[1]->triangleCount(), 4u * 4u);
  for (int threads : kThreadCounts) {
    const anim::SceneSources loaded = withThreads(threads, [&] { return anim::loadSceneSources(scene); });
    ASSERT_EQ(loaded.sources.size(), reference.sources.size());
    EXPECT_EQ(loaded.objectSource, reference.objectSource);
    EXPECT_EQ(loaded.sourceBytes, reference.sourceBytes);
    for (std::size_t s = 0; s < loaded.sources.size(); ++s) {
      const auto& got = *loaded.sources[s];
      const auto& want = *reference.sources[s];
      EXPECT_TRUE(std::equal(got.indices().begin(), got.indices().end(), want.indices().begin(), want.indices().end()));
      EXPECT_EQ(got.keyframe(0), want.keyframe(0)) << "source " << s << ", " << threads << " threads";
    }
  }
}

std::string loadError(const std::string& scene) {
  try {
    anim::loadSceneSources(scene);
  } catch (const tsah::Error& e) {
    return e.what();
  }
  return "";
}

TEST(ParallelSceneLoad, TheErrorIsTheFirstObjectsInSceneOrder) {
  const fs::path dir = tsah::test::scratchDir();
  writeMeshes(dir);
  // A later object's load fails, an earlier one's subdivision fails: the earlier one is named.
  tsah::test::writeText(dir / "subdivision_first.json", R"({"objects": [
    {"name": "good", "file": "tetra.obj", "subdivide": 2},
    {"name": "fin", "file": "fin.obj", "subdivide": 1},
    {"name": "missing", "file": "missing.obj"}]})");
  // The other way round.
  tsah::test::writeText(dir / "load_first.json", R"({"objects": [
    {"name": "missing", "file": "missing.obj"},
    {"name": "fin", "file": "fin.obj", "subdivide": 1}]})");
  for (int threads : kThreadCounts) {
    const std::string first = withThreads(threads, [&] { return loadError((dir / "subdivision_first.json").string()); });
    EXPECT_NE(first.find("object 'fin': "), std::string::npos) << first;
    EXPECT_NE(first.find("non-manifold edge"), std::string::npos) << first;
    const std::string second = withThreads(threads, [&] { return loadError((dir / "load_first.json").string()); });
    EXPECT_NE(second.find("object 'missing': "), std::string::npos) << second;
  }
}

TEST(ParallelTwoLevelBuild, SameFileBytesForEveryThreadCount) {
  const fs::path dir = tsah::test::scratchDir();
  const fs::path scene = tsah::test::writeTwoLevelScene(dir);
  tsah::TreeOptions options = tsah::test::smallTwoLevelOptions();
  options.optimizer = tsah::OptimizerKind::Parallel;
  options.threads = 0;  // the optimizer's arena: what the global control allows
  const auto encoded = [&](int threads) {
    tsah::TwoLevelScene built =
        withThreads(threads, [&] { return tsah::loadTwoLevelScene(scene.string(), {}, options); });
    for (tsah::Blas& blas : built.blases) blas.info.buildSeconds = 0.0;
    for (tsah::TlasTree& t : built.tlases) t.info.buildSeconds = 0.0;
    return tsah::encodeTwoLevelScene(built);
  };
  const std::vector<uint8_t> reference = encoded(1);
  for (int threads : kThreadCounts) EXPECT_EQ(encoded(threads), reference) << threads << " threads";
}

}  // namespace
