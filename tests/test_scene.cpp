// Scene files: placement, paths, time mapping, instancing, subdivision, the memory statement and
// bad input (docs/scenes.md).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "tsah/base/error.hpp"
#include "anim/load.hpp"
#include "anim/point_cache.hpp"
#include "anim/scene.hpp"
#include "anim/subdivide.hpp"
#include "anim/tanim.hpp"
#include "test_support.hpp"

namespace fs = std::filesystem;

namespace {

using tsah::test::writeText;

// One triangle (1,0,0) (0,1,0) (0,0,1) as an OBJ.
fs::path triangleObj(const fs::path& dir) {
  writeText(dir / "tri.obj", "v 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n");
  return dir / "tri.obj";
}

// A triangle whose first vertex moves x = 1 + t over t in [0, 1] (keyframes at 0, 0.5, 1); the
// others never move.
fs::path movingTanim(const fs::path& dir) {
  std::vector<float> pos;
  for (float t : {0.0f, 0.5f, 1.0f}) pos.insert(pos.end(), {1 + t, 0, 0, 0, 1, 0, 0, 0, 1});
  anim::saveTanim(anim::Animation({0, 1, 2}, 3, pos, {0.0, 0.5, 1.0}, "mover"), (dir / "mover.tanim").string());
  return dir / "mover.tanim";
}

std::string sceneWith(const std::string& objects, const std::string& extra = "\"fps\": 4") {
  return "{" + extra + ", \"objects\": [" + objects + "]}";
}

// The error message of loading `scene`, or "" when it loads.
std::string loadError(const fs::path& scene) {
  try {
    anim::load(scene.string());
  } catch (const tsah::FileError& e) {
    return e.what();
  }
  return "";
}

TEST(Scene, OneObjectEqualsLoadingItDirectly) {
  const fs::path dir = tsah::test::scratchDir();
  movingTanim(dir);
  writeText(dir / "one.json", sceneWith(R"({"file": "mover.tanim"})", "\"fps\": 2"));
  const auto direct = anim::load((dir / "mover.tanim").string());
  const auto scene = anim::load((dir / "one.json").string());
  EXPECT_TRUE(anim::isSceneFile((dir / "one.json").string()));
  ASSERT_EQ(scene.keyframeCount(), direct.keyframeCount());
  EXPECT_EQ(std::vector<double>(scene.times().begin(), scene.times().end()),
            std::vector<double>(direct.times().begin(), direct.times().end()));
  EXPECT_EQ(scene.allPositions(), direct.allPositions());
  EXPECT_EQ(std::vector<uint32_t>(scene.indices().begin(), scene.indices().end()),
            std::vector<uint32_t>(direct.indices().begin(), direct.indices().end()));
  EXPECT_EQ(scene.movingVertexCount(), 1u);  // the source's static vertices stay static

  triangleObj(dir);
  writeText(dir / "static.json", sceneWith(R"({"file": "tri.obj"})"));
  const auto mesh = anim::load((dir / "tri.obj").string());
  const auto s = anim::load((dir / "static.json").string());
  EXPECT_EQ(s.keyframeCount(), 1u);
  EXPECT_EQ(s.allPositions(), mesh.allPositions());
}

TEST(Scene, StaticPlacementIsTheHandComputedTransform) {
  const fs::path dir = tsah::test::scratchDir();
  triangleObj(dir);
  writeText(dir / "s.json", sceneWith(R"({"file": "tri.obj", "transform": {"translate": [1, 2, 3], "rotate": [0, 0, 90], "scale": 2}},
                                     {"file": "tri.obj", "transform": {"matrix": [0, 0, 1, 5,  1, 0, 0, 0,  0, 1, 0, 0,  0, 0, 0, 1]}})"));
  const auto a = anim::load((dir / "s.json").string());
  ASSERT_EQ(a.vertexCount(), 6u);
  ASSERT_EQ(a.triangleCount(), 2u);
  EXPECT_EQ(a.movingVertexCount(), 0u);
  const auto p = a.positionsAt(0.0);
  // scale 2, then 90 degrees about z ((x, y) -> (-y, x)), then translate.
  const float expected[18] = {1, 4, 3, -1, 2, 3, 1, 2, 5,
                              // matrix rows: x' = z + 5, y' = x, z' = y
                              5, 1, 0, 5, 0, 1, 6, 0, 0};
  for (int i = 0; i < 18; ++i) EXPECT_NEAR(p[i], expected[i], 1e-6) << i;
}

TEST(Scene, KeyedPathMovesTheObject) {
  const fs::path dir = tsah::test::scratchDir();
  triangleObj(dir);
  writeText(dir / "s.json", sceneWith(R"({"file": "tri.obj", "path": [{"time": 0}, {"time": 2, "translate": [10, 0, 0], "rotate": [0, 0, 180]}]})"));
  const auto a = anim::load((dir / "s.json").string());
  EXPECT_EQ(a.keyframeCount(), 9u);  // [0, 2] at 4 fps
  EXPECT_EQ(a.movingVertexCount(), 3u);
  // t = 1: translate 5, rotate 90 about z: (1,0,0) -> (0,1,0) -> (5,1,0).
  const auto p = a.positionsAt(1.0);
  EXPECT_NEAR(p[0], 5.0f, 1e-5);
  EXPECT_NEAR(p[1], 1.0f, 1e-5);
  EXPECT_NEAR(p[8], 1.0f, 1e-5);  // (0,0,1) keeps z
  const auto e = a.positionsAt(2.0);  // (1,0,0) rotated 180 + 10 -> (9, 0, 0)
  EXPECT_NEAR(e[0], 9.0f, 1e-5);
  EXPECT_NEAR(e[1], 0.0f, 1e-5);
}

TEST(Scene, OffsetLoopAndHoldMapSceneTime) {
  const fs::path dir = tsah::test::scratchDir();
  movingTanim(dir);
  writeText(dir / "s.json", sceneWith(R"({"name": "late", "file": "mover.tanim", "time": {"offset": 0.5}},
                                     {"name": "fast", "file": "mover.tanim", "time": {"speed": 2, "outside": "loop"}},
                                     {"name": "held", "file": "mover.tanim", "transform": {"translate": [0, 0, 10]}})",
                                  "\"fps\": 8, \"time\": [0, 2]"));
  const auto baked = anim::bakeScene((dir / "s.json").string());
  const auto& a = baked.animation;
  EXPECT_EQ(baked.distinctSources, 1u);
  EXPECT_EQ(a.keyframeCount(), 17u);
  EXPECT_EQ(a.movingVertexCount(), 3u);  // one per instance
  // Vertex 0 of each object: x = 1 + local time.
  auto x = [&](double t, int object) { return a.positionsAt(t)[9 * object]; };
  EXPECT_FLOAT_EQ(x(0.25, 0), 1.0f);   // before its offset: holds its start
  EXPECT_FLOAT_EQ(x(1.0, 0), 1.5f);    // local 0.5
  EXPECT_FLOAT_EQ(x(2.0, 0), 2.0f);    // past its end: holds
  EXPECT_FLOAT_EQ(x(0.25, 1), 1.5f);   // speed 2
  EXPECT_FLOAT_EQ(x(0.75, 1), 1.5f);   // local 1.5 loops to 0.5
  EXPECT_FLOAT_EQ(x(1.25, 1), 1.5f);   // local 2.5 loops to 0.5
  EXPECT_FLOAT_EQ(x(2.0, 2), 2.0f);    // hold
  EXPECT_FLOAT_EQ(a.positionsAt(2.0)[9 * 2 + 2], 10.0f);
}

TEST(Scene, InstancesShareTheirSource) {
  const fs::path dir = tsah::test::scratchDir();
  movingTanim(dir);
  writeText(dir / "s.json", sceneWith(R"({"name": "herd", "file": "mover.tanim", "instances": [
      {"transform": {"translate": [0, 0, 0]}}, {"transform": {"translate": [5, 0, 0]}, "offset": 0.5},
      {"transform": {"translate": [10, 0, 0]}, "path": [{"time": 0}, {"time": 1, "translate": [0, 3, 0]}]}]},
      {"name": "again", "file": "./mover.tanim"})", "\"fps\": 2, \"time\": [0, 1]"));
  const auto baked = anim::bakeScene((dir / "s.json").string());
  EXPECT_EQ(baked.distinctSources, 1u);
  ASSERT_EQ(baked.objects.size(), 2u);
  EXPECT_EQ(baked.objects[0].instances, 3u);
  EXPECT_EQ(baked.objects[0].triangles, 3u);
  EXPECT_EQ(baked.objects[0].movingVertices, 1u + 1u + 3u);  // the keyed one moves whole
  EXPECT_EQ(baked.animation.triangleCount(), 4u);
  const auto p = baked.animation.positionsAt(1.0);
  EXPECT_FLOAT_EQ(p[0], 2.0f);
  EXPECT_FLOAT_EQ(p[9], 5 + 1.5f);
  EXPECT_FLOAT_EQ(p[18], 10 + 2.0f);
  EXPECT_FLOAT_EQ(p[19], 3.0f);
  EXPECT_EQ(baked.statement.triangles, 4u);
  EXPECT_EQ(baked.statement.animationBytes, baked.animation.memoryBytes());
}

TEST(Scene, SourcesAndInstancesWithoutBakingAreWhatTheBakeBakes) {
  const fs::path dir = tsah::test::scratchDir();
  movingTanim(dir);
  triangleObj(dir);
  writeText(dir / "s.json", sceneWith(R"({"name": "herd", "file": "mover.tanim", "instances": [
      {}, {"transform": {"translate": [5, 0, 0]}, "offset": 0.5},
      {"path": [{"time": 0}, {"time": 3, "translate": [0, 3, 0]}]}]},
      {"name": "rock", "file": "tri.obj", "transform": {"scale": [1, -2, 1]}},
      {"name": "again", "file": "./mover.tanim", "time": {"speed": 2}})", "\"fps\": 2"));
  const anim::SceneSources loaded = anim::loadSceneSources((dir / "s.json").string());
  ASSERT_EQ(loaded.sources.size(), 2u);  // mover.tanim once, tri.obj once
  EXPECT_EQ(loaded.objectSource, (std::vector<uint32_t>{0, 1, 0}));
  ASSERT_EQ(loaded.instances.size(), 5u);
  EXPECT_EQ(loaded.instances[1].object, 0u);
  EXPECT_EQ(loaded.instances[3].object, 1u);
  EXPECT_EQ(loaded.instances[4].source, 0u);
  EXPECT_DOUBLE_EQ(loaded.instances[1].time.offset, 0.5);
  EXPECT_DOUBLE_EQ(loaded.instances[4].localTime(0.25, *loaded.sources[0]), 0.5);
  EXPECT_DOUBLE_EQ(loaded.instances[2].worldAt(1.5)[7], 1.5);  // halfway along the path
  EXPECT_DOUBLE_EQ(loaded.end, 3.0);
  EXPECT_EQ(loaded.frameCount, 7u);
  // The bake holds, instance after instance, each source at its local time moved by world(t).
  const anim::BakedScene baked = anim::bakeScene((dir / "s.json").string());
  const std::vector<double> times = loaded.frameTimes();
  ASSERT_EQ(times.size(), baked.animation.keyframeCount());
  for (std::size_t k = 0; k < times.size(); ++k) {
    EXPECT_DOUBLE_EQ(times[k], baked.animation.times()[k]);
    const std::vector<float> flat = baked.animation.positionsAt(times[k]);
    std::size_t at = 0;
    for (const anim::SceneSourceInstance& i : loaded.instances) {
      const anim::Animation& source = loaded.sourceOf(i);
      std::vector<float> p = source.positionsAt(i.localTime(times[k], source));
      anim::transformPoints(i.worldAt(times[k]), p.data(), source.vertexCount());
      for (float c : p) EXPECT_FLOAT_EQ(flat[at++], c);
    }
    EXPECT_EQ(at, flat.size());
  }
}

// An octahedron inscribed in the unit sphere.
anim::Animation octahedron() {
  std::vector<float> p{1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1};
  std::vector<uint32_t> idx{0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5};
  return anim::Animation(idx, 6, p, {0.0}, "octahedron");
}

TEST(Scene, LoopSubdivisionCountsAndStaysCloseToTheSurface) {
  const auto o = octahedron();
  const auto c = anim::meshCounts(o);
  EXPECT_EQ(c.edges, 12u);
  for (uint32_t levels : {1u, 2u, 3u}) {
    const auto s = anim::subdivideLoop(o, levels);
    EXPECT_EQ(s.triangleCount(), 8u << (2 * levels));
    const auto expected = anim::loopSubdividedCounts(c, levels);
    EXPECT_EQ(s.vertexCount(), expected.vertices);
    EXPECT_EQ(s.triangleCount(), expected.triangles);
  }
  // A 128-triangle sphere (the octahedron subdivided twice, projected on the unit sphere): Loop
  // keeps it convex and close to the sphere.
  const auto fine = anim::subdivideLoop(o, 2);
  std::vector<float> p = fine.keyframe(0);
  for (std::size_t i = 0; i < p.size(); i += 3) {
    const float r = std::sqrt(p[i] * p[i] + p[i + 1] * p[i + 1] + p[i + 2] * p[i + 2]);
    for (int a = 0; a < 3; ++a) p[i + a] /= r;
  }
  const anim::Animation sphere({fine.indices().begin(), fine.indices().end()}, fine.vertexCount(), p, {0.0});
  for (uint32_t levels : {1u, 2u, 3u}) {
    const auto s = anim::subdivideLoop(sphere, levels);
    EXPECT_EQ(s.triangleCount(), 128u << (2 * levels));
    const auto q = s.keyframe(0);
    for (std::size_t i = 0; i < q.size(); i += 3) {
      const double r = std::sqrt(double(q[i]) * q[i] + double(q[i + 1]) * q[i + 1] + double(q[i + 2]) * q[i + 2]);
      EXPECT_LE(r, 1.0 + 1e-6);
      EXPECT_GE(r, 0.93);  // the 128-triangle mesh's own face centres lie at about 0.93
    }
  }
  EXPECT_THROW(anim::subdivideLoop(anim::Animation({0, 1, 2}, 3, std::vector<float>(18, 0.0f), {0.0, 1.0}), 1),
               tsah::Error);
}

TEST(Scene, SubdivideInASceneFile) {
  const fs::path dir = tsah::test::scratchDir();
  anim::saveTanim(octahedron(), (dir / "octa.tanim").string());
  writeText(dir / "s.json", sceneWith(R"({"file": "octa.tanim", "subdivide": 2, "instances": [{}, {"transform": {"translate": [3, 0, 0]}}]})"));
  const auto baked = anim::bakeScene((dir / "s.json").string());
  EXPECT_EQ(baked.animation.triangleCount(), 2u * 8 * 16);
  EXPECT_EQ(baked.objects[0].sourceTriangles, 8u * 16);
  EXPECT_EQ(baked.objects[0].subdivisionLevels, 2u);
}

struct BadCase {
  const char* name;
  const char* objects;
  const char* expect;  // a part of the message
};

TEST(Scene, BadInputNamesTheSceneFileAndTheObject) {
  const fs::path dir = tsah::test::scratchDir();
  triangleObj(dir);
  movingTanim(dir);
  std::string many;
  for (int i = 0; i < 2000; ++i)
    many += std::string(i ? "," : "") + R"({"path": [{"time": 0}, {"time": 1, "translate": [1, 0, 0]}]})";
  const std::string hugeInstances =
      R"({"name": "bad", "file": "mover.tanim", "instances": [)" + many + "]}";
  const BadCase cases[] = {
      {"missing", R"({"name": "bad", "file": "nowhere.obj"})", "no such file"},
      {"singular", R"({"name": "bad", "file": "tri.obj", "transform": {"scale": [1, 0, 1]}})", "not invertible"},
      {"singular-matrix", R"({"name": "bad", "file": "tri.obj", "transform": {"matrix": [1,2,3,0, 2,4,6,0, 0,0,1,0, 0,0,0,1]}})", "not invertible"},
      {"overflow", R"({"name": "bad", "file": "tri.obj", "transform": {"scale": 1e200}})", "infinite"},
      {"negative-speed", R"({"name": "bad", "file": "mover.tanim", "time": {"speed": -1}})", "negative speed"},
      {"zero-path-scale", R"({"name": "bad", "file": "tri.obj", "path": [{"time": 0, "scale": 0}]})", "zero scale"},
      {"keys-backwards", R"({"name": "bad", "file": "tri.obj", "path": [{"time": 1}, {"time": 0}]})", "increasing"},
      {"subdivide-animated", R"({"name": "bad", "file": "mover.tanim", "subdivide": 1})", "static mesh"},
      {"subdivide-memory", R"({"name": "bad", "file": "tri.obj", "subdivide": 14})", "would need"},
      {"subdivide-count", R"({"name": "bad", "file": "tri.obj", "subdivide": 16})", "2^32"},
      {"offset-twice", R"({"name": "bad", "file": "mover.tanim", "offset": 1, "time": {"offset": 2}})",
       R"(both "offset" and "time": {"offset"} are given; keep one)"},
      {"offset-twice-instance", R"({"name": "bad", "file": "mover.tanim", "instances": [{"offset": 1, "time": {"offset": 2}}]})",
       R"(both "offset" and "time": {"offset"} are given; keep one)"},
  };
  for (const BadCase& c : cases) {
    const fs::path scene = dir / (std::string(c.name) + ".json");
    writeText(scene, sceneWith(c.objects));
    const std::string message = loadError(scene);
    EXPECT_NE(message.find(scene.string() + ": "), std::string::npos) << c.name << ": " << message;
    EXPECT_NE(message.find("bad"), std::string::npos) << c.name << ": " << message;
    EXPECT_NE(message.find(c.expect), std::string::npos) << c.name << ": " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << c.name;
  }
  // JSON has no NaN or infinity: an overflowing number is a JSON error of the file.
  writeText(dir / "inf.json", sceneWith(R"({"name": "bad", "file": "tri.obj", "transform": {"translate": [1e999, 0, 0]}})"));
  EXPECT_NE(loadError(dir / "inf.json").find((dir / "inf.json").string() + ": not valid JSON"), std::string::npos)
      << loadError(dir / "inf.json");
  // 2000 moving instances x 1,000,001 keyframes: about 70 GiB, refused by the statement.
  const fs::path big = dir / "big.json";
  writeText(big, sceneWith(hugeInstances, "\"fps\": 1000000, \"time\": [0, 1]"));
  const std::string message = loadError(big);
  EXPECT_NE(message.find("object 'bad': 2000 instances"), std::string::npos) << message;
  EXPECT_NE(message.find("MiB of memory available"), std::string::npos) << message;
}

TEST(Scene, ScenesIncludingEachOtherAreACycle) {
  const fs::path dir = tsah::test::scratchDir();
  triangleObj(dir);
  writeText(dir / "a.json", sceneWith(R"({"file": "tri.obj"}, {"name": "inner", "file": "b.json"})"));
  writeText(dir / "b.json", sceneWith(R"({"name": "back", "file": "a.json"})"));
  const std::string message = loadError(dir / "a.json");
  EXPECT_NE(message.find("include each other"), std::string::npos) << message;
  EXPECT_NE(message.find("object 'inner'"), std::string::npos) << message;
  writeText(dir / "self.json", sceneWith(R"({"name": "me", "file": "self.json"})"));
  EXPECT_NE(loadError(dir / "self.json").find("object 'me': scene files include each other"), std::string::npos);
  // A scene of a scene (no cycle) composes.
  writeText(dir / "outer.json", sceneWith(R"({"file": "b2.json", "transform": {"translate": [0, 0, 1]}})"));
  writeText(dir / "b2.json", sceneWith(R"({"file": "tri.obj"})"));
  EXPECT_FLOAT_EQ(anim::load((dir / "outer.json").string()).positionsAt(0.0)[8], 2.0f);
}

TEST(Scene, DataPathsResolveThroughTheOption) {
  const fs::path dir = tsah::test::scratchDir();
  triangleObj(dir);
  writeText(dir / "s.json", sceneWith(R"({"file": "data:somewhere/tri.obj"})"));
  anim::LoadOptions options;
  options.resolveDataPath = [&](const std::string& rel) {
    EXPECT_EQ(rel, "somewhere/tri.obj");
    return (dir / "tri.obj").string();
  };
  EXPECT_EQ(anim::load((dir / "s.json").string(), options).triangleCount(), 1u);
}

TEST(Scene, DataPathsStayInsideTheDataFolder) {
  const fs::path dir = tsah::test::scratchDir();
  triangleObj(dir);
  fs::create_directories(dir / "data");
  fs::create_symlink(dir, dir / "data" / "out");  // a link leading out of the data folder
  const char* old = std::getenv("TSAH_DATA_DIR");
  const std::string saved = old ? old : "";
  ::setenv("TSAH_DATA_DIR", (dir / "data").c_str(), 1);
  const struct {
    std::string file, expect;
  } cases[] = {
      {"data:../tri.obj", R"("data:../tri.obj" must name a path inside the data folder (relative, without ".."))"},
      {"data:/etc/passwd", R"("data:/etc/passwd" must name a path inside the data folder (relative, without ".."))"},
      {"data:", R"("data:" must name a path inside the data folder (relative, without ".."))"},
      {"data:out/tri.obj", ("\"data:out/tri.obj\" leads to " + fs::canonical(dir / "tri.obj").string() +
                            ", outside the data folder (through a symbolic link)")},
  };
  for (const auto& c : cases) {
    writeText(dir / "s.json", sceneWith("{\"name\": \"bad\", \"file\": \"" + c.file + "\"}"));
    EXPECT_EQ(loadError(dir / "s.json"), (dir / "s.json").string() + ": object 'bad': " + c.expect);
  }
  if (old) ::setenv("TSAH_DATA_DIR", saved.c_str(), 1);
  else ::unsetenv("TSAH_DATA_DIR");
  // The resolver of the options never sees a path that climbs out.
  anim::LoadOptions options;
  options.resolveDataPath = [](const std::string& rel) -> std::string { ADD_FAILURE() << rel; return rel; };
  writeText(dir / "s.json", sceneWith(R"({"name": "bad", "file": "data:a/../../tri.obj"})"));
  EXPECT_THROW(anim::load((dir / "s.json").string(), options), tsah::FileError);
}

TEST(Scene, EmptyFileIsRefused) {
  const fs::path dir = tsah::test::scratchDir();
  writeText(dir / "s.json", sceneWith(R"({"name": "bad", "file": ""})"));
  EXPECT_EQ(loadError(dir / "s.json"), (dir / "s.json").string() +
                                           ": object 'bad': \"file\" is empty (name an input, relative to the "
                                           "scene file's folder)");
}

TEST(Scene, MeshAndCacheResolveAgainstTheScenesFolder) {
  const fs::path dir = tsah::test::scratchDir() / "elsewhere";
  fs::create_directories(dir);
  triangleObj(dir);
  anim::Animation mover = anim::load(movingTanim(dir).string());
  anim::savePointCache(mover, (dir / "tri.pc2").string());
  writeText(dir / "s.json", sceneWith(R"({"file": "tri.obj+tri.pc2"})", "\"fps\": 2"));
  const anim::Animation a = anim::load((dir / "s.json").string());
  EXPECT_EQ(a.keyframeCount(), 3u);
  EXPECT_FLOAT_EQ(a.positionsAt(1.0)[0], 2.0f);
}

}  // namespace
