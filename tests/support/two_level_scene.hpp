#pragma once
// The two-level test scene shared by the CPU and GPU two-level tests: two sources (a static ground
// and an animated cloth) placed with rotations, non-uniform scales, a mirrored placement, keyed
// paths and time offsets, the small tree options they build it with, and the TLAS box holding each
// instance.
#include <filesystem>
#include <random>
#include <sstream>
#include <span>
#include <vector>

#include "anim/tanim.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/pipeline.hpp"
#include "test_support.hpp"

namespace tsah::test {

// Sources: a static mesh (the first frame of a generated wave, one keyframe) and an animated one
// (a generated wave over keyframes at 0..8). The scene places them with rotations, non-uniform
// scales, a mirrored placement, keyed paths (ending at 12, after the animation's last frame), and
// instances of the animated source with different time offsets (two of them showing one pose).
inline std::filesystem::path writeTwoLevelScene(const std::filesystem::path& dir) {
  const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 300, 9, 3);
  anim::saveTanim(wave, (dir / "wave.tanim").string());
  const std::vector<float> first = wave.positionsAt(wave.startTime());
  const std::vector<uint32_t> indices(wave.indices().begin(), wave.indices().end());
  anim::saveTanim(anim::Animation(indices, wave.vertexCount(), first, {0.0}, "ground"), (dir / "ground.tanim").string());
  tsah::test::writeText(dir / "scene.json", R"({"fps": 2, "objects": [
    {"name": "ground", "file": "ground.tanim", "instances": [
      {"transform": {"translate": [0, -1, 0], "rotate": [10, 20, 30], "scale": [3, 0.5, 2]}},
      {"transform": {"matrix": [-1, 0, 0, 4,  0, 1, 0, 0,  0, 0, 1, 1,  0, 0, 0, 1]}},
      {"transform": {"translate": [2, 1, -2]},
       "path": [{"time": 0}, {"time": 12, "translate": [1, 2, 3], "rotate": [0, 90, 0], "scale": [1, 2, 1]}]}]},
    {"name": "cloth", "file": "wave.tanim", "instances": [
      {"transform": {"translate": [0, 2, 0]}},
      {"offset": 1.5, "transform": {"translate": [0, 2, 4], "rotate": [0, 45, 0], "scale": [1, 1, -1]}},
      {"time": {"offset": 3, "outside": "loop"}, "transform": {"rotate": [90, 0, 0], "scale": [0.5, 2, 1]},
       "path": [{"time": 0}, {"time": 6, "translate": [0, 1, 0]}, {"time": 12, "translate": [-3, 0, 1], "rotate": [0, 0, 45]}]},
      {"transform": {"translate": [5, 2, 0], "scale": [1, 1.5, 1]}}]}
  ]})");
  return dir / "scene.json";
}

// A crowd beside the small scene's sources (writeTwoLevelScene's wave.tanim and ground.tanim in
// `dir`): 48 waves, each with its own time offset (a pose each), every third walking a path, and 16
// static grounds, on a grid.
inline std::filesystem::path writeCrowdScene(const std::filesystem::path& dir) {
  std::ostringstream cloth, ground;
  for (uint32_t i = 0; i < 48; ++i) {
    const float x = 3.0f * float(i % 8), z = 3.0f * float(i / 8);
    cloth << (i ? ",\n" : "") << R"({"offset": )" << 0.25 * i << R"(, "transform": {"translate": [)" << x << ", 0, " << z
          << "]}";
    if (i % 3 == 0) cloth << R"(, "path": [{"time": 0}, {"time": 12, "translate": [)" << (i % 2 ? 6 : -6) << ", 0, 4]}]";
    cloth << "}";
  }
  for (uint32_t i = 0; i < 16; ++i)
    ground << (i ? ",\n" : "") << R"({"transform": {"translate": [)" << 6.0f * float(i % 4) << ", -1, "
           << 6.0f * float(i / 4) << "]}}";
  tsah::test::writeText(dir / "crowd.json", R"({"fps": 2, "objects": [
    {"name": "ground", "file": "ground.tanim", "instances": [)" + ground.str() + R"(]},
    {"name": "cloth", "file": "wave.tanim", "instances": [)" + cloth.str() + "]}]}");
  return dir / "crowd.json";
}

inline tsah::TreeOptions smallTwoLevelOptions() {
  tsah::TreeOptions options;
  options.frames = 3;
  options.objective.k = 2;
  options.objective.maxLeafSize = 4;
  options.threads = 2;
  return options;
}

// Rigid motion only, after the animation ends: two instances of a generated wave (keyframes 0..4,
// 4 fps), one moved along a keyed path to t = 8 (translated and turned), one offset by 1 and
// mirrored; both poses reach their last frame by t = 5 and hold it while the path moves on.
inline std::filesystem::path writeRigidPathScene(const std::filesystem::path& dir) {
  const anim::Animation wave = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, 200, 5, 2);
  anim::saveTanim(wave, (dir / "wave.tanim").string());
  tsah::test::writeText(dir / "s.json", R"({"fps": 4, "objects": [{"file": "wave.tanim", "instances": [
    {"path": [{"time": 0}, {"time": 8, "translate": [5, 0, 0], "rotate": [0, 180, 0]}]},
    {"offset": 1, "transform": {"scale": [-1, 1, 1]}}]}]})");
  return dir / "s.json";
}

// Static only, nothing on a path: nothing moves in any shutter.
inline std::filesystem::path writeStillScene(const std::filesystem::path& dir) {
  const anim::Animation wave = generatedAnimation(anim::GeneratorKind::Wave, 100, 2, 4);
  const std::vector<uint32_t> indices(wave.indices().begin(), wave.indices().end());
  anim::saveTanim(anim::Animation(indices, wave.vertexCount(), wave.positionsAt(wave.startTime()), {0.0}, "ground"),
                  (dir / "ground.tanim").string());
  writeText(dir / "still.json", R"({"fps": 2, "time": [0, 2], "objects": [{"file": "ground.tanim", "instances": [
    {"transform": {"rotate": [10, 20, 30], "scale": [3, 0.5, 2]}}, {"transform": {"scale": [-1, 1, 1], "translate": [0, 1, 0]}}]}]})");
  return dir / "still.json";
}

// One triangle, (1,0,0) (0,1,0) (0,0,1), whose path scales x from 1 to -1 over t = 0..2 (2 fps): at
// t = 1 the instance is flat (a singular world transform), at t = 2 mirrored.
inline std::filesystem::path writeFlattenedTriangleScene(const std::filesystem::path& dir) {
  tsah::test::writeText(dir / "tri.obj", "v 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n");
  tsah::test::writeText(dir / "s.json", R"({"fps": 2, "objects": [{"file": "tri.obj",
    "path": [{"time": 0}, {"time": 2, "scale": [-1, 1, 1]}]}]})");
  return dir / "s.json";
}

// The TLAS box holding each instance (its leaf's box in the parent node, or the root box).
inline std::vector<tsah::Aabb> tlasLeafBoxes(const tsah::FlatBvh& tlas) {
  std::vector<tsah::Aabb> out(tlas.triangleCount());
  auto assign = [&](int32_t ref, uint32_t count, const tsah::Aabb& box) {
    for (uint32_t s = tsah::leafFirstSlot(ref); s < tsah::leafFirstSlot(ref) + count; ++s) out[tlas.triIndex[s]] = box;
  };
  if (tlas.interiorCount == 0) assign(tlas.rootRef, tlas.rootCount, tlas.rootBoxes[0]);
  for (uint32_t n = 0; n < tlas.interiorCount; ++n)
    for (int c = 0; c < 2; ++c)
      if (tsah::isLeafRef(tlas.nodes[n].childRef(c)))
        assign(tlas.nodes[n].childRef(c), tlas.nodes[n].childCount(c), tlas.nodes[n].childBox(c));
  return out;
}

// Rays from random points around the scene's box to random points inside it (most hit something).
inline std::vector<tsah::Ray> raysThroughBox(const tsah::Aabb& bounds, uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const tsah::Vec3 e = bounds.extent();
  auto around = [&](float spread) {
    return tsah::Vec3{bounds.lo.x + e.x * (spread * unit(rng) + 0.5f * (1 - spread)),
                      bounds.lo.y + e.y * (spread * unit(rng) + 0.5f * (1 - spread)),
                      bounds.lo.z + e.z * (spread * unit(rng) + 0.5f * (1 - spread))};
  };
  std::vector<tsah::Ray> rays(count);
  for (tsah::Ray& ray : rays) {
    ray.org = around(2.0f);
    ray.dir = around(1.0f) - ray.org;  // unnormalized
    ray.tmin = 0.0f;
    ray.tmax = 1e30f;
  }
  return rays;
}

inline tsah::Aabb unionOf(std::span<const tsah::Aabb> boxes) {
  tsah::Aabb all;
  for (const tsah::Aabb& b : boxes) all.extend(b);
  return all;
}

}  // namespace tsah::test
