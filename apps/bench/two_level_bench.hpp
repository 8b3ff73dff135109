#pragma once
// The two-level part of `tsah bench` (docs/bench.md): for a scene file (docs/scenes.md), the flat
// tree against the two-level structure (docs/two-level.md) and Embree instancing, on the CPU.
//
// Optimization: `tsah optimize SCENE --structure flat` and `--structure two-level` as child
// processes of options.program (their wall time, build time and peak resident memory: the whole
// command's, as the scaling mode measures it); the trees stay in OUT/trees/ for the GPU bench.
// Per traced frame (scene frames spread evenly over the scene's time: there the baked flat scene
// holds exactly the two-level scene's positions), every tracer on the same rays (the renderer's
// primary, AO and shadow rays, made from the flat runtime's hits):
//   flat       CpuRuntime over the baked scene: the frame's positions and refit (+ Woop);
//   two-level  TwoLevelRuntime: update(t) (the poses that changed refitted, transforms, TLAS refit);
//   embree-instanced  EmbreeInstancedPeer (embree_instanced.hpp): the poses' vertices and refit
//              commits, instance transforms, top level committed.
// Reported: update, trace, total per frame, rays/s, the agreement of the ray results (two-level
// and Embree against flat, Embree against two-level), the host TLAS rebuild (rebuildTlas) per
// frame as the reference of the TLAS refit, and the ratios.
#include <filesystem>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "bench/bench.hpp"

namespace tsah::bench {

// Runs the part for the scene file scene.input (`baked`: its baked animation, as benchScene loaded
// it). Throws tsah::ConfigError without options.program, tsah::Failure when an optimization fails.
nlohmann::json runTwoLevelComparison(const SceneSource& scene, const anim::Animation& baked, const BenchOptions& options,
                                     const std::filesystem::path& outDir, const BenchProgress& progress);

}  // namespace tsah::bench
