#pragma once
// Helpers shared by the test executables.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <memory>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "anim/animation.hpp"
#include "anim/generators.hpp"

#include "tsah/io/tree_set.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/optimize/parallel_optimizer.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/render/renderer.hpp"

namespace tsah::test {

// A generated animation (anim::generate) of about `triangles` triangles over `frames` keyframes.
anim::Animation generatedAnimation(anim::GeneratorKind kind, uint32_t triangles, uint32_t frames, uint64_t seed = 1);

// A scene with a big static part: a generated wave mesh at rest (about `staticTriangles`, never
// moving: stored once as rest positions) next to an exploding mesh (about `movingTriangles`, 5
// keyframes), so that most of a tree over it never moves.
anim::Animation mostlyStaticAnimation(uint32_t staticTriangles = 4000, uint32_t movingTriangles = 1000);

// The real-data folder (../shared/data by default, TSAH_DATA_DIR in the environment overrides).
std::filesystem::path dataDir();

// Unpacks data/<relative archive> (a .tar.xz) once into the build tree and returns the folder it
// made; empty when the data folder or archive is absent (the caller then GTEST_SKIPs).
std::filesystem::path unpackedData(const std::string& archive, const std::string& folder);

// A fresh empty directory under the system temp dir, unique to the running test.
std::filesystem::path scratchDir();

// Writes `text` to `path` (bytes as given), creating its folder; returns the path.
std::filesystem::path writeText(const std::filesystem::path& path, std::string_view text);

// Success when `action` throws tsah::FileError whose message holds every one of `parts`; the failure
// says what it threw instead, or that it threw nothing. Other exceptions pass through.
::testing::AssertionResult throwsFileError(const std::function<void()>& action,
                                           std::initializer_list<std::string_view> parts);

// anim's bounds (a.bounds(), a.boundsAt(t), ...) as a box.
Aabb boxOf(const anim::Bounds& b);
// The triangles' boxes at keyframe k.
std::vector<Aabb> keyframeBoxes(const anim::Animation& a, uint32_t k);

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
// The case's tree twice, for the two halves of the animation's time range, as a set read from a
// file: tree 0's build info has the case's objective, tree 1's the default one.
TreeSet twoPartObjectiveSet(const WideObjectiveCase& c);
// The host's compressed 8-wide tree of `tree` for `objective`, made as the CPU wide layouts make
// theirs: WideCollapser(wideCollapseConfig(objective, 8)) over every frame, then buildCwbvh.
CwbvhTree hostCwbvh(const FlatBvh& tree, const Objective& objective);
// The same nodes (bytes) and triangle order.
bool sameCwbvh(const CwbvhTree& a, const CwbvhTree& b);

// Same root, nodes (links, leaf ranges) and primIds.
bool sameTopology(const Bvh& a, const Bvh& b);
// sameTopology, the same frame count and every box bit for bit.
bool identicalTree(const Bvh& a, const Bvh& b);

// The optimizer sessions' grid: seeds 1, 2, 3 x `frameCounts` x k = 0, 2, each case on
// movingTriangleBoxes(triangles + perSeed * seed, frames, seed). Stops at the first fatal failure.
using SeedFramesK = std::function<void(const PrimitiveBoxes& prims, uint32_t seed, int k)>;
void forEachSeedFramesAndK(std::initializer_list<uint32_t> frameCounts, uint32_t triangles, uint32_t perSeed,
                           const SeedFramesK& body);

// A round session on `tree` (the sweep-SAH tree of frame 0 of prims) for `config`, searching a
// `candidateFraction` of the nodes per round.
using MakeRoundSession =
    std::function<std::unique_ptr<RoundSession>(Bvh tree, const PrimitiveBoxes& prims,
                                                const ParallelReinsertionOptimizer::Config& config,
                                                double candidateFraction)>;
// Over forEachSeedFramesAndK({1, 4}, 150, 100) with config {k, seed} and candidate fraction 1 for
// seed 3, else 0.5: 12 rounds of expectValidRounds that apply moves, end below the start cost, and
// are counted by appliedMoves().
void expectRoundsValidAndImproving(const MakeRoundSession& make);

// A parallel-reinsertion run (any backend) from `tree`, the sweep-SAH tree of frame 0 of prims.
using RunOptimizer = std::function<InsertionOptimizer::Result(Bvh tree, const PrimitiveBoxes& prims,
                                                              const ParallelReinsertionOptimizer::Config& config)>;
// For k = 0, 1, 4 on movingTriangleBoxes(800, 5, 7 + k), `run` with config.k = k gives a valid tree
// below the start cost, a history of two or more entries that never rises, and a final cost equal to
// C~^k recomputed from the tree; then `alsoCheck` (when given) runs on the result.
void expectRunsNeverEndAboveTheStart(const RunOptimizer& run,
                                     const std::function<void(const InsertionOptimizer::Result&)>& alsoCheck = {});

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

// The render tests' frame: `a`'s box, a 203 x 157 image (not a multiple of the 8 x 4 tiles) with 5
// AO and 3 shadow rays per pixel, and the camera fitted to the box (y up, 45 degrees).
struct RenderView {
  Aabb bounds;
  RenderSettings settings;
  Camera camera;
};
RenderView renderView(const anim::Animation& a);

// Two exact tracers rendering the same frame: the same primary rays; AO and shadow ray counts within
// 0.2% + 8 (a primary tie, another triangle at the same distance, changes a pixel's normal).
void expectRayCountsClose(const RenderStats& got, const RenderStats& expect);
// Images of the same frame: mean channel difference below 0.2, at most 0.2% of the channels off by
// more than 16. `what` names the case in the failure messages.
void expectImagesClose(const Image& a, const Image& b, const std::string& what);

}  // namespace tsah::test
