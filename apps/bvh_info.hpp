#pragma once
// `tsah info` on a .tbvh file: the header and a few derived figures, as text or one JSON object.
#include <string>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "tsah/bvh_file.hpp"
#include "tsah/tree_set.hpp"

namespace tsah::cli {

// True when the file starts with the .tbvh magic (so `tsah info` can dispatch on content).
bool looksLikeBvhFile(const std::string& path);

// The header of a decoded file as JSON (the fields of docs/tbvh-format.md, plus leaf statistics).
nlohmann::json describeBvh(const tsah::FlatBvh& flat, const tsah::BvhBuildInfo& info);

// Loads and validates `path` (throws anim::ImportError naming the file) and prints its header on
// stdout: aligned text, or one JSON object when json is true. A tree set (version 2) prints the
// set's header and then each tree with the time range it is used for.
void describeBvhFile(const std::string& path, bool json);

// Throws anim::Error with one clear line when the animation is not the one the tree was built for
// (triangle count, vertex count or topology hash differ).
void checkTreeMatchesAnimation(const tsah::BvhBuildInfo& info, const std::string& bvhPath, const anim::Animation& a,
                               const std::string& animationPath);

}  // namespace tsah::cli
