#include "test_support.hpp"

#include "tsah/build/sah_builder.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <unistd.h>

#include "tsah/base/error.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/render/sampling.hpp"

namespace tsah::test {

anim::Animation generatedAnimation(anim::GeneratorKind kind, uint32_t triangles, uint32_t frames, uint64_t seed) {
  anim::GeneratorOptions o;
  o.triangles = triangles;
  o.frames = frames;
  o.seed = seed;
  return anim::generate(kind, o);
}

anim::Animation mostlyStaticAnimation(uint32_t staticTriangles, uint32_t movingTriangles) {
  const auto still = generatedAnimation(anim::GeneratorKind::Wave, staticTriangles, 1, 3);
  const auto mover = generatedAnimation(anim::GeneratorKind::Explode, movingTriangles, 5, 4);
  std::vector<uint32_t> idx(still.indices().begin(), still.indices().end());
  for (uint32_t v : mover.indices()) idx.push_back(v + still.vertexCount());
  std::vector<float> pos;
  const std::vector<float> rest = still.keyframe(0);
  for (uint32_t k = 0; k < mover.keyframeCount(); ++k) {
    pos.insert(pos.end(), rest.begin(), rest.end());
    const auto m = mover.keyframe(k);
    pos.insert(pos.end(), m.begin(), m.end());
  }
  return anim::Animation(idx, still.vertexCount() + mover.vertexCount(), pos,
                         {mover.times().begin(), mover.times().end()}, "mostly-static");
}

std::filesystem::path dataDir() {
  if (const char* env = std::getenv("TSAH_DATA_DIR")) return env;
  return TSAH_DATA_DIR;
}

std::filesystem::path unpackedData(const std::string& archive, const std::string& folder) {
  namespace fs = std::filesystem;
  const fs::path source = dataDir() / archive;
  if (!fs::exists(source)) return {};
  const fs::path cache = fs::temp_directory_path() / ("tsah-test-data-" + std::to_string(::getuid()));
  const fs::path out = cache / folder;
  if (fs::exists(out / ".complete")) return out;
  // Unpack into a private folder and rename it into place, so parallel tests never see half a tree.
  const fs::path staging = cache / ("staging-" + std::to_string(::getpid()));
  fs::remove_all(staging);
  fs::create_directories(staging);
  const std::string cmd = "tar -xJf '" + source.string() + "' -C '" + staging.string() + "'";
  if (std::system(cmd.c_str()) != 0 || !fs::exists(staging / folder)) return {};
  if (std::FILE* marker = std::fopen((staging / folder / ".complete").c_str(), "w")) std::fclose(marker);
  std::error_code ec;
  fs::rename(staging / folder, out, ec);  // fails harmlessly when another test won the race
  fs::remove_all(staging, ec);
  if (!fs::exists(out / ".complete")) return {};
  return out;
}

std::filesystem::path scratchDir() {
  namespace fs = std::filesystem;
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "tsah";
  for (char& c : name)
    if (c == '/') c = '_';
  const fs::path dir = fs::temp_directory_path() /
                       ("tsah-" + std::to_string(::getpid()) + "-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::filesystem::path writeText(const std::filesystem::path& path, std::string_view text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

::testing::AssertionResult throwsFileError(const std::function<void()>& action,
                                           std::initializer_list<std::string_view> parts) {
  try {
    action();
  } catch (const FileError& e) {
    const std::string message = e.what();
    for (std::string_view part : parts)
      if (message.find(part) == std::string::npos)
        return ::testing::AssertionFailure() << "the error '" << message << "' lacks '" << part << "'";
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure() << "no tsah::FileError thrown";
}

Aabb boxOf(const anim::Bounds& b) {
  Aabb box;
  box.extend(Vec3{b.min[0], b.min[1], b.min[2]});
  box.extend(Vec3{b.max[0], b.max[1], b.max[2]});
  return box;
}

std::vector<Aabb> keyframeBoxes(const anim::Animation& a, uint32_t k) {
  std::vector<Aabb> boxes(a.triangleCount());
  triangleBoxes(a.indices(), a.keyframe(k), boxes);
  return boxes;
}

MovingTriangles randomMovingTriangles(uint32_t triangles, uint32_t frames, uint32_t seed, float maxSpeed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(-20.0f, 20.0f), small(-1.0f, 1.0f), vel(-maxSpeed, maxSpeed);
  MovingTriangles s;
  s.frames = frames;
  const uint32_t vertices = triangles * 3;
  for (uint32_t i = 0; i < vertices; ++i) s.indices.push_back(i);
  s.positions.resize(std::size_t(frames) * vertices * 3);
  for (uint32_t t = 0; t < triangles; ++t) {
    const float c[3] = {pos(rng), pos(rng), pos(rng)};
    const float v[3] = {vel(rng), vel(rng), vel(rng)};
    for (uint32_t corner = 0; corner < 3; ++corner) {
      const float o[3] = {small(rng), small(rng), small(rng)};
      for (uint32_t f = 0; f < frames; ++f)
        for (int a = 0; a < 3; ++a)
          s.positions[(std::size_t(f) * vertices + t * 3 + corner) * 3 + a] = c[a] + o[a] + v[a] * float(f);
    }
  }
  return s;
}

PrimitiveBoxes movingTriangleBoxes(uint32_t triangles, uint32_t frames, uint32_t seed) {
  return randomMovingTriangles(triangles, frames, seed, 4.0f).boxes();
}

Bvh frameZeroSahTree(const PrimitiveBoxes& prims) { return SweepSahBuilder().build(prims.frame(0)); }

FlatBvh singleLeafTree(const anim::Animation& a) {
  Bvh leaf;
  leaf.nodes.resize(1);
  leaf.nodes[0].primCount = a.triangleCount();
  for (uint32_t i = 0; i < a.triangleCount(); ++i) leaf.primIds.push_back(i);
  leaf.boxes.resize(1);
  for (const Aabb& b : keyframeBoxes(a, 0)) leaf.boxes[0].extend(b);
  return flattenBvh(leaf);
}

WideObjectiveCase wideObjectiveCase() {
  anim::Animation a = generatedAnimation(anim::GeneratorKind::Explode, 3000, 6);
  const PrimitiveBoxes boxes = triangleBoxes(a.indices(), a.allPositions(), a.keyframeCount());
  Bvh bvh = SweepSahBuilder().build(boxes.frame(0));
  refit(bvh, boxes);
  Objective objective;
  objective.k = 2;
  objective.cost = {4.0f, 1.0f};
  objective.maxLeafSize = 6;
  FlatBvh tree = flattenBvh(bvh);
  return {std::move(a), std::move(tree), objective};
}

TreeSet twoPartObjectiveSet(const WideObjectiveCase& c) {
  const anim::Animation& a = c.animation;
  TreeSet set;
  set.trees = {c.tree, c.tree};
  const double mid = 0.5 * (a.startTime() + a.endTime());
  set.ranges = {{a.startTime(), mid}, {mid, a.endTime()}};
  set.builds.resize(2);
  set.builds[0].objective = c.objective;
  return set;
}

CwbvhTree hostCwbvh(const FlatBvh& tree, const Objective& objective) {
  return buildCwbvh(WideCollapser(wideCollapseConfig(objective, kCwbvhWidth)).collapse(unflattenBvh(tree)));
}

bool sameCwbvh(const CwbvhTree& a, const CwbvhTree& b) {
  return a.nodes.size() == b.nodes.size() &&
         std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(CwbvhNode)) == 0 &&
         a.triIndex == b.triIndex;
}

FlatBvh tinyTree(const MovingTriangles& m, const std::vector<uint32_t>& leafSizes) {
  const uint32_t n = uint32_t(m.indices.size() / 3);
  Bvh bvh;
  bvh.frameCount = 1;
  bvh.primIds.resize(n);
  for (uint32_t i = 0; i < n; ++i) bvh.primIds[i] = i;
  bvh.nodes.resize(leafSizes.size() == 1 ? 1 : 3);
  if (leafSizes.size() == 1) {
    bvh.nodes[0].primCount = n;
  } else {
    bvh.nodes[0].left = 1;
    bvh.nodes[0].right = 2;
    bvh.nodes[1] = {};
    bvh.nodes[1].parent = 0;
    bvh.nodes[1].primCount = leafSizes[0];
    bvh.nodes[2] = {};
    bvh.nodes[2].parent = 0;
    bvh.nodes[2].primBegin = leafSizes[0];
    bvh.nodes[2].primCount = leafSizes[1];
  }
  bvh.boxes.resize(bvh.nodes.size());
  refit(bvh, m.boxes());
  return flattenBvh(bvh);
}

bool sameTopology(const Bvh& a, const Bvh& b) {
  if (a.root != b.root || a.nodes.size() != b.nodes.size() || a.primIds != b.primIds) return false;
  for (std::size_t n = 0; n < a.nodes.size(); ++n) {
    const BvhNode &x = a.nodes[n], &y = b.nodes[n];
    if (x.parent != y.parent || x.left != y.left || x.right != y.right || x.primBegin != y.primBegin ||
        x.primCount != y.primCount)
      return false;
  }
  return true;
}

bool identicalTree(const Bvh& a, const Bvh& b) {
  return sameTopology(a, b) && a.frameCount == b.frameCount && a.boxes.size() == b.boxes.size() &&
         std::memcmp(a.boxes.data(), b.boxes.data(), a.boxes.size() * sizeof(Aabb)) == 0;
}

void forEachSeedFramesAndK(std::initializer_list<uint32_t> frameCounts, uint32_t triangles, uint32_t perSeed,
                           const SeedFramesK& body) {
  for (uint32_t seed : {1u, 2u, 3u})
    for (uint32_t frames : frameCounts)
      for (int k : {0, 2}) {
        SCOPED_TRACE("seed " + std::to_string(seed) + " frames " + std::to_string(frames) + " k " + std::to_string(k));
        body(movingTriangleBoxes(triangles + perSeed * seed, frames, seed), seed, k);
        if (::testing::Test::HasFatalFailure()) return;
      }
}

void expectRoundsValidAndImproving(const MakeRoundSession& make) {
  forEachSeedFramesAndK({1u, 4u}, 150, 100, [&](const PrimitiveBoxes& prims, uint32_t seed, int k) {
    ParallelReinsertionOptimizer::Config config;
    config.k = k;
    config.seed = seed;
    const std::unique_ptr<RoundSession> session = make(frameZeroSahTree(prims), prims, config, seed == 3 ? 1.0 : 0.5);
    const double start = session->cost();
    const uint64_t applied = expectValidRounds(*session, prims, k, 12);
    EXPECT_GT(applied, 0u);
    EXPECT_LT(session->cost(), start);
    EXPECT_EQ(session->appliedMoves(), applied);
  });
}

void expectRunsNeverEndAboveTheStart(const RunOptimizer& run,
                                     const std::function<void(const InsertionOptimizer::Result&)>& alsoCheck) {
  for (int k : {0, 1, 4}) {
    SCOPED_TRACE("k " + std::to_string(k));
    const PrimitiveBoxes prims = movingTriangleBoxes(800, 5, 7 + k);
    ParallelReinsertionOptimizer::Config config;
    config.k = k;
    const InsertionOptimizer::Result result = run(frameZeroSahTree(prims), prims, config);
    ASSERT_FALSE(validate(result.bvh, &prims).has_value());
    EXPECT_LT(result.finalCost, result.initialCost);
    ASSERT_GE(result.history.size(), 2u);
    for (std::size_t i = 1; i < result.history.size(); ++i)
      EXPECT_LE(result.history[i].cost, result.history[i - 1].cost * (1 + 1e-12));
    EXPECT_NEAR(result.finalCost, temporalCost(frameCosts(result.bvh), k), 1e-9 * result.finalCost);
    if (alsoCheck) alsoCheck(result);
  }
}

uint64_t expectValidRounds(RoundSession& session, const PrimitiveBoxes& prims, int k, int rounds, double tolerance) {
  uint64_t applied = 0;
  double previous = session.cost();
  for (int round = 0; round < rounds; ++round) {
    const auto stats = session.round();
    applied += stats.applied;
    EXPECT_LE(stats.applied, stats.winners);
    EXPECT_LE(stats.winners, stats.improving);
    EXPECT_LE(stats.improving, stats.candidates);
    const Bvh tree = session.bvh();
    const auto problem = validate(tree, &prims);
    EXPECT_FALSE(problem.has_value()) << "round " << round << ": " << *problem;
    if (problem) return applied;
    const std::vector<double> perFrame = frameCosts(tree);
    const std::vector<double> tracked = session.frameCostList();
    for (uint32_t f = 0; f < prims.frameCount; ++f)
      EXPECT_NEAR(tracked[f], perFrame[f], tolerance * perFrame[f]) << "round " << round << " frame " << f;
    const double expected = temporalCost(perFrame, k);
    EXPECT_NEAR(session.cost(), expected, tolerance * expected) << "round " << round;
    EXPECT_LE(session.cost(), previous * (1 + 1e-12)) << "round " << round << " raised the cost";
    session.endRound();
    EXPECT_NEAR(session.cost(), expected, tolerance * expected) << "new weights changed the cost";
    previous = session.cost();
  }
  return applied;
}

std::vector<WoopTriangle> cwbvhWoop(const CwbvhTree& t, std::span<const uint32_t> idx, std::span<const float> pos) {
  std::vector<WoopTriangle> w(t.triIndex.size());
  for (size_t s = 0; s < w.size(); ++s) {
    const uint32_t* tri = idx.data() + 3 * std::size_t(t.triIndex[s]);
    auto v = [&](uint32_t i) { return Vec3{pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]}; };
    w[s] = makeWoopTriangle(v(tri[0]), v(tri[1]), v(tri[2]));
  }
  return w;
}

std::vector<Ray> randomRays(const BvhView& v, uint32_t triangles, const Aabb& b, uint32_t count, std::mt19937& rng) {
  std::normal_distribution<float> g;
  auto unit = [&] { return normalize(Vec3{g(rng), g(rng), g(rng)}); };
  std::uniform_real_distribution<float> u01(0, 1);
  const float diag = std::sqrt(dot(b.extent(), b.extent()));
  std::vector<Ray> rays(count);
  for (uint32_t i = 0; i < count; ++i) {
    Ray& ray = rays[i];
    if (i % 3 == 0) {
      const uint32_t* tri = v.indices + 3 * (rng() % triangles);
      const Vec3 target = (v.vertex(tri[0]) + v.vertex(tri[1]) + v.vertex(tri[2])) * (1.0f / 3.0f);
      ray.org = b.center() + unit() * diag;
      ray.dir = target - ray.org;
    } else {
      ray.org = b.lo + Vec3{u01(rng) * b.extent().x, u01(rng) * b.extent().y, u01(rng) * b.extent().z};
      ray.dir = unit() * (0.1f + 3.0f * u01(rng));
    }
    if (i % 7 == 3) {  // axis-aligned: zero direction components (invDir is then +-1e30)
      ray.dir[int(rng() % 3)] = 0.0f;
      if (i % 2 == 0) ray.dir[int(rng() % 3)] = 0.0f;
      if (ray.dir.x == 0.0f && ray.dir.y == 0.0f && ray.dir.z == 0.0f) ray.dir.z = -1.0f;
    }
    ray.tmin = i % 5 == 2 ? 0.01f * u01(rng) : 0.0f;
    ray.tmax = i % 4 == 0 ? u01(rng) * 2.0f : 3.4e38f;
  }
  return rays;
}

HitAgreement expectSameHits(const BvhView& binary, const CwbvhView& wide, std::span<const Ray> rays) {
  HitAgreement a;
  for (const Ray& ray : rays) {
    const Hit expect = closestHit(binary, ray);
    const Hit got = cwbvhClosestHit(wide, ray);
    EXPECT_EQ(expect.valid(), got.valid());
    EXPECT_EQ(anyHit(binary, ray), cwbvhAnyHit(wide, ray));
    if (!expect.valid() || !got.valid()) continue;
    ++a.hits;
    EXPECT_EQ(expect.t, got.t);
    if (expect.tri != got.tri) {
      ++a.ties;
      continue;
    }
    EXPECT_EQ(expect.u, got.u);
    EXPECT_EQ(expect.v, got.v);
  }
  return a;
}

void expectWideTraversalMatchesBinary(const anim::Animation& a, CpuRuntime& rt, uint32_t rayCount, uint32_t seed,
                                      const WideTreeAt& wideAt) {
  std::mt19937 rng(seed);
  uint32_t hits = 0, ties = 0;
  for (double time : {a.startTime(), 0.37 * a.endTime(), a.endTime()}) {
    const auto pos = a.positionsAt(time);
    rt.update(pos);
    const BvhView bv = rt.view();
    const CwbvhTree& t = wideAt(pos, bv);
    const auto woop = cwbvhWoop(t, a.indices(), pos);
    const CwbvhView cv = t.view(woop.data(), a.indices().data(), pos.data());
    const HitAgreement agree = expectSameHits(bv, cv, randomRays(bv, a.triangleCount(), rt.bounds(), rayCount, rng));
    hits += agree.hits;
    ties += agree.ties;
  }
  EXPECT_GT(hits, rayCount / 4);
  EXPECT_LE(ties, hits / 100 + 5);
}

RenderView renderView(const anim::Animation& a) {
  RenderView view;
  view.bounds = boxOf(a.bounds());
  view.settings.width = 203;
  view.settings.height = 157;
  view.settings.aoSamples = 5;
  view.settings.shadowSamples = 3;
  view.camera = fitCamera(view.bounds, {0, 1, 0}, 45.0f, float(view.settings.width) / float(view.settings.height));
  return view;
}

void expectRayCountsClose(const RenderStats& got, const RenderStats& expect) {
  EXPECT_EQ(got.primary.rays, expect.primary.rays);
  EXPECT_NEAR(double(got.ao.rays), double(expect.ao.rays), 0.002 * double(expect.ao.rays) + 8);
  EXPECT_NEAR(double(got.shadow.rays), double(expect.shadow.rays), 0.002 * double(expect.shadow.rays) + 8);
}

void expectImagesClose(const Image& a, const Image& b, const std::string& what) {
  const ImageDifference d = compareImages(a, b, 16);
  EXPECT_LT(d.meanAbs, 0.2) << what;
  EXPECT_LT(d.fractionAbove, 0.002) << what;
}

}  // namespace tsah::test
