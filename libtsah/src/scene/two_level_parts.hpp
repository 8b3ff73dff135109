#pragma once
// Private to libtsah: the steps of a two-level structure that building it and reading it from a
// file share.
#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "tsah/scene/two_level.hpp"

namespace tsah {

// Wall seconds since `start` (the build's phases and trees).
double secondsSince(std::chrono::steady_clock::time_point start);
// Throws tsah::Failure ("WHAT: invalid tree: ...") unless tsah::validate accepts the tree over `prims`.
void requireValid(const Bvh& bvh, const PrimitiveBoxes& prims, const std::string& what);
// Poses and instancePose from the scene's time mappings (out.blases must be set).
void assignPoses(const anim::SceneSources& scene, TwoLevelScene& out);
// Every instance's world box at every frame of out.frameTimes (out.blases must be set).
PrimitiveBoxes instanceBoxesOverFrames(const anim::SceneSources& scene, const TwoLevelScene& out);
// Every BLAS's and the TLAS's frame costs and C~^k (static BLAS with k = 0).
void computeLevelCosts(TwoLevelScene& out);
// The TLAS header's topology hash: CRC-32 of the instances' source ids.
uint32_t instanceTableHash(const anim::SceneSources& scene);

// The scene frames inside `range`, both ends included: (first, count).
std::pair<uint32_t, uint32_t> framesInside(std::span<const double> frameTimes, const TimeRange& range);
// Frames first .. first + count - 1 of `boxes`.
PrimitiveBoxes frameSlice(const PrimitiveBoxes& boxes, uint32_t first, uint32_t count);
// out.tlases built as `tlas` asks over out.instanceBoxes (out.frameTimes and objective set).
void buildTlasTrees(const anim::SceneSources& scene, TwoLevelScene& out, const TreeOptions& options,
                    const TlasOptions& tlas);
// Eq. 1 at each scene frame of the TLAS used there (TwoLevelScene::tlasAt).
std::vector<double> tlasFrameCosts(const TwoLevelScene& out);

}  // namespace tsah
