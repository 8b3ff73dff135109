#pragma once
// Glue between anim::Animation and libtsah's builders shared by the commands: frames of an
// animation as a lazily filled tsah::FrameSource, and the node-selection names of the CLI.
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "tsah/baselines.hpp"
#include "tsah/insertion_optimizer.hpp"

namespace tsah::cli {

// Triangle boxes of `animation` at each of `times`, produced on demand (in parallel by the caller).
// The animation must outlive the returned source.
FrameSource animationFrames(const anim::Animation& animation, std::vector<double> times);

// The triangle boxes of `frames` representative frames, uniform in time (the resampled animation
// is freed before returning, so it is never held alongside the tree being built).
PrimitiveBoxes representativeBoxes(const anim::Animation& animation, uint32_t frames);

// "mh", "random", "batch" -> the optimizer's node selection; throws std::invalid_argument for anything else.
InsertionOptimizer::Selection parseSelection(const std::string& name);

}  // namespace tsah::cli
