#pragma once
// The commands' and the bench's names for libtsah's animation glue (tsah/pipeline.hpp): frames of
// an animation as a lazily filled tsah::FrameSource, and the node-selection names of the CLI.
#include "tsah/pipeline.hpp"

namespace tsah::cli {

using tsah::animationFrames;
using tsah::animationTimeline;

}  // namespace tsah::cli
