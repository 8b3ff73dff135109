#pragma once
// Helpers shared by the test executables.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "anim/generators.hpp"
#include <functional>
#include <random>
#include <span>

#include "tsah/core/bvh.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"
#include "tsah/layout/traversal.hpp"

namespace tsah::test {

// A generated animation (anim::generate) of about `triangles` triangles over `frames` keyframes.
anim::Animation generatedAnimation(anim::GeneratorKind kind, uint32_t triangles, uint32_t frames, uint64_t seed = 1);

// The real-data folder (../shared/data by default, TSAH_DATA_DIR in the environment overrides).
std::filesystem::path dataDir();

// Unpacks data/<relative archive> (a .tar.xz) once into the build tree and returns the folder it
// made; empty when the data folder or archive is absent (the caller then GTEST_SKIPs).
std::filesystem::path unpackedData(const std::string& archive, const std::string& folder);

// A fresh empty directory under the system temp dir, unique to the running test.
std::filesystem::path scratchDir();

// Random small triangles (3 own vertices each) moving with random constant velocities, so a grouping
// made on frame 0 degrades over time: the standard input of the optimizer and cost tests.
// positions holds `frames` blocks of triangles*3 vertices (xyz).
struct MovingTriangles {
  std::vector<uint32_t> indices;
  std::vector<float> positions;
  uint32_t frames = 0;

  PrimitiveBoxes boxes() const { return triangleBoxes(indices, positions, frames); }
};
MovingTriangles randomMovingTriangles(uint32_t triangles, uint32_t frames, uint32_t seed, float maxSpeed);
// The optimizer tests' input: randomMovingTriangles(triangles, frames, seed, 4).boxes().
PrimitiveBoxes movingTriangleBoxes(uint32_t triangles, uint32_t frames, uint32_t seed);
// The optimizers' starting tree: the sweep-SAH tree of frame 0 (frame 0's boxes only).
Bvh frameZeroSahTree(const PrimitiveBoxes& prims);
// The animation's triangles in one leaf (the root), boxed on keyframe 0, in flat form.
FlatBvh singleLeafTree(const anim::Animation& a);
// m's triangles (one frame) in one leaf (leafSizes {n}) or two leaves under a root (sizes {a, b},
// a + b = n), in flat form.
FlatBvh tinyTree(const MovingTriangles& m, const std::vector<uint32_t>& leafSizes);

// The input of the tests that the compressed 8-wide collapse follows a tree's objective
// (test_cwbvh on the host, test_cuda_cwbvh on the GPU): an exploding animation, its sweep-SAH tree
// of keyframe 0 (one triangle per leaf) with the boxes of every keyframe, and an objective (k = 2,
// cT and cI other than 3 and 2, leaves of at most 6) whose collapse of that tree differs from the
// default objective's and from the one with k = 0 (test_cwbvh checks both).
struct WideObjectiveCase {
  anim::Animation animation;
  FlatBvh tree;
  Objective objective;
};
WideObjectiveCase wideObjectiveCase();
// The host's compressed 8-wide tree of `tree` for `objective`, made as the CPU wide layouts make
// theirs: WideCollapser(wideCollapseConfig(objective, 8)) over every frame, then buildCwbvh.
CwbvhTree hostCwbvh(const FlatBvh& tree, const Objective& objective);
// The same nodes (bytes) and triangle order.
bool sameCwbvh(const CwbvhTree& a, const CwbvhTree& b);

// Same root, nodes (links, leaf ranges) and primIds.
bool sameTopology(const Bvh& a, const Bvh& b);
// sameTopology, the same frame count and every box bit for bit.
bool identicalTree(const Bvh& a, const Bvh& b);

// Runs `rounds` rounds (each followed by endRound) of a reinsertion session and checks after every
// one: a valid tree (each primitive in one leaf, parent links, boxes containing their children in
// every frame), tracked frame costs and C~^k equal to a brute-force recomputation (relative
// `tolerance`), no round raising the cost, the stats' order. Returns the moves applied.
uint64_t expectValidRounds(RoundSession& session, const PrimitiveBoxes& prims, int k, int rounds,
                           double tolerance = 1e-9);

// Woop triangles per slot of a compressed wide tree, at the given positions.
std::vector<WoopTriangle> cwbvhWoop(const CwbvhTree& t, std::span<const uint32_t> indices,
                                    std::span<const float> positions);

// Rays as in test_traversal: a third from outside at random triangles, the others from inside the
// box in any direction; some with tmin > 0 or a short tmax.
std::vector<Ray> randomRays(const BvhView& v, uint32_t triangles, const Aabb& box, uint32_t count, std::mt19937& rng);

// Traces every ray with the binary CPU traversal and the compressed wide one and asserts the same
// validity, any-hit answer and distance (bit for bit: the same triangle test on the same Woop
// data), and u, v where the triangle is the same. Returns the hits and the ties (a different
// triangle at exactly the same distance: shared edges and vertices visited in another order).
struct HitAgreement {
  uint32_t hits = 0, ties = 0;
};
HitAgreement expectSameHits(const BvhView& binary, const CwbvhView& wide, std::span<const Ray> rays);

// At three times of `a` (start, 0.37 * end, end): updates rt (the binary CPU runtime of a tree for
// `a`), gets the compressed tree for those positions from wideAt, and runs expectSameHits on
// rayCount random rays; then expects a quarter of the rays to hit and ties in at most 1% + 5.
using WideTreeAt = std::function<const CwbvhTree&(std::span<const float> positions, const BvhView& binary)>;
void expectWideTraversalMatchesBinary(const anim::Animation& a, CpuRuntime& rt, uint32_t rayCount, uint32_t seed,
                                      const WideTreeAt& wideAt);

}  // namespace tsah::test
