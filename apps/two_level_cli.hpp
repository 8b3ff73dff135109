#pragma once
// Two-level scenes on the command line (docs/two-level.md): `tsah optimize --structure`, `tsah info`
// of a version 3 .tbvh file with its scene, and the frame runtimes `tsah trace` uses for one (CPU
// and GPU).
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "anim/scene.hpp"
#include "frame_runtime.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/scene/structure_choice.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"

namespace tsah::cli {

// True when `path` is a .tbvh file of version 3 (a two-level scene).
bool isTwoLevelTreeFile(const std::string& path);

// The scene's sources and instances with the command line's load options (fps, clip, data folder).
anim::SceneSources loadSceneSourcesForCli(const std::string& scenePath);

// --structure auto (docs/two-level.md): tsah::chooseObjectStructure with the command's cost model
// and leaf size. Every object flattened: a flat tree; else two levels, the chosen objects flattened.
StructureChoice chooseStructure(const anim::SceneSources& scene, const TreeOptions& options);
// The decision as JSON (per object: instances, moves, costs, flatten, reason) and as text lines.
nlohmann::json describeStructureChoice(const StructureChoice& choice);
void printStructureChoice(const nlohmann::json& j);

// `tsah optimize SCENE --structure two-level|auto`: flattens the objects `choice` chose (none when
// asked for two levels: choice null), builds and writes the version 3 file and prints the structure
// (text, or one JSON object) with the decision, the top-level trees as `tlas` asks, and the wall time of every phase (loadSeconds: the
// caller's loading of the scene's sources). reproducible: every tree's build time written as 0.
void optimizeTwoLevel(anim::SceneSources scene, const std::string& input, const std::string& output,
                      const TreeOptions& options, const TlasOptions& tlas, const StructureChoice* choice, bool json,
                      double loadSeconds, bool reproducible);

// The structure as JSON: BLAS (static / animated, each one's cost and bytes), instances, poses, the
// TLAS cost over the scene frames, the bytes of each level.
nlohmann::json describeTwoLevel(const TwoLevelScene& scene);

// `tsah info TREE SCENE` for a version 3 TREE.
void describeTwoLevelFile(const std::string& treePath, const std::string& scenePath, bool json);

// The frame runtime of a two-level scene on the CPU (TwoLevelRuntime + the renderer's loop through
// it). Owns the scene. A shutter fraction above 0 blurs every frame: TwoLevelRuntime::updateShutter
// over shutterInterval of the scene's time range with frameInterval, the time between traced frames.
std::unique_ptr<FrameRuntime> makeTwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, Layout layout,
                                                       unsigned threads, TwoLevelRuntime::TlasUpdate tlas,
                                                       std::optional<TriangleForm> poseTriangles = {},
                                                       Shutter shutter = {}, double frameInterval = 0.0);

// The frame runtime of a two-level scene on GPU `gpu` (GpuTwoLevelRuntime + GpuTwoLevelRenderer,
// two_level_gpu_frame.cpp): BLAS in `layout` (bvh2 or cwbvh; auto: bvh2), the TLAS in bvh2. Owns the
// scene. Throws tsah::ConfigError in a build without CUDA, tsah::Failure on a machine without a GPU.
// tlas: "refit" (the T-SAH TLAS refitted), "lbvh" or "hlbvh-sah" (a TLAS built every frame on the GPU).
// A shutter fraction above 0 blurs every frame as the CPU's runtime does (updateShutter).
std::unique_ptr<FrameRuntime> makeGpuTwoLevelFrameRuntime(std::shared_ptr<const TwoLevelScene> scene, int gpu,
                                                          Layout layout, const std::string& tlas, Shutter shutter = {},
                                                          double frameInterval = 0.0);

}  // namespace tsah::cli
