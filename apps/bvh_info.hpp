#pragma once
// `tsah info` on a .tbvh file: the header and a few derived figures, as text or one JSON object.
#include <string>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/io/tree_set.hpp"

namespace tsah::cli {

// True when the file starts with the .tbvh magic (so `tsah info` can dispatch on content).
bool looksLikeBvhFile(const std::string& path);

// The header of a decoded file as JSON (the fields of docs/tbvh-format.md, plus leaf statistics).
nlohmann::json describeBvh(const tsah::FlatBvh& flat, const tsah::BvhBuildInfo& info);

// Loads and validates `path` (throws tsah::FileError naming the file) and prints its header on
// stdout: aligned text, or one JSON object when json is true. A tree set (version 2) prints the
// set's header and then each tree with the time range it is used for.
void describeBvhFile(const std::string& path, bool json);

// `tsah info TREE ANIMATION`: the tree's shape and, for each of `frames` uniformly spaced frames of
// the animation (0: every keyframe), its cost with the interior/leaf split, the area-weighted mean
// depth and size of the leaves and the growth of the root's children (tsah/tree_quality.hpp), as an
// aligned table or one JSON object.
void describeTreeOverAnimation(const std::string& bvhPath, const std::string& animationPath, uint32_t frames, bool json);

// The library's check that a tree was built for an animation (tsah/pipeline.hpp).
using tsah::checkTreeMatchesAnimation;

}  // namespace tsah::cli
