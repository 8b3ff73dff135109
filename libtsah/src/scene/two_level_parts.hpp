#pragma once
// Private to libtsah: the steps of a two-level structure that building it and reading it from a
// file share.
#include <cstdint>

#include "tsah/scene/two_level.hpp"

namespace tsah {

// Poses and instancePose from the scene's time mappings (out.blases must be set).
void assignPoses(const anim::SceneSources& scene, TwoLevelScene& out);
// Every instance's world box at every frame of out.frameTimes (out.blases must be set).
PrimitiveBoxes instanceBoxesOverFrames(const anim::SceneSources& scene, const TwoLevelScene& out);
// Every BLAS's and the TLAS's frame costs and C~^k (static BLAS with k = 0).
void computeLevelCosts(TwoLevelScene& out);
// The TLAS header's topology hash: CRC-32 of the instances' source ids.
uint32_t instanceTableHash(const anim::SceneSources& scene);

}  // namespace tsah
