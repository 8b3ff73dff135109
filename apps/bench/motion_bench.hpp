#pragma once
// The motion-blur part of `tsah bench` (docs/bench.md): per traced frame the toolkit refits its
// tree at the shutter's key times (tsah::updateShutter) and traces the renderer's rays at each
// pixel's time; Embree traces the same rays at the same times with its motion-blur BVH built once
// over the whole animation (the keyframes as time steps) and with one rebuilt every frame over the
// shutter's keys. Reported: update, trace and frame times, rays/s, the ratios of the toolkit to
// Embree, and how many rays find what the toolkit finds (the rest classified).
#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "bench/ray_batch.hpp"
#include "bench/runtime_bench.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/pipeline.hpp"

namespace tsah::bench {

// Two results for the same rays: how many agree, and of the primary rays that do not, why.
struct Agreement {
  uint64_t primaryRays = 0, primarySame = 0;
  uint64_t ties = 0;        // both hit, another triangle at (nearly) the same t: the traversal order decides
  uint64_t oneMisses = 0;   // one hits, the other misses: the ray grazes an edge (precision)
  uint64_t otherDepth = 0;  // both hit at different t: one passes an edge the other closes (precision)
  uint64_t occlusionRays = 0, occlusionSame = 0;  // AO and shadow rays: the same occluded or not
  uint64_t rays() const { return primaryRays + occlusionRays; }
  uint64_t same() const { return primarySame + occlusionSame; }
  double fraction() const { return rays() ? double(same()) / double(rays()) : 1.0; }
  // Adds one frame: `other` against the toolkit's `own` (the same batch).
  void add(const BatchTrace& own, const BatchTrace& other);
};

// Two hits at t within this relative difference count as a tie.
inline constexpr float kTieRelative = 1e-4f;

nlohmann::json toJson(const Agreement& agreement);

// Runs the part on setup.times (at least two: the shutter is a fraction of the time between them)
// with `tree` refitted by the toolkit. Without Embree only the toolkit's row, and
// "embree_status" says why. Throws tsah::ConfigError for fewer than two frames or a shutter
// fraction outside (0, 1].
nlohmann::json runMotionBlurComparison(const anim::Animation& animation, const Bvh& tree, const std::string& label,
                                       const RuntimeSetup& setup, const Shutter& shutter);

}  // namespace tsah::bench
