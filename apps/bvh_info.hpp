#pragma once
// `tsah info` on a .tbvh file: the header and a few derived figures, as text or one JSON object.
#include <string>

#include <nlohmann/json.hpp>

#include "anim/animation.hpp"
#include "tsah/bvh_file.hpp"
#include "tsah/pipeline.hpp"

namespace tsah::cli {

// True when the file starts with the .tbvh magic (so `tsah info` can dispatch on content).
bool looksLikeBvhFile(const std::string& path);

// The header of a decoded file as JSON (the fields of docs/tbvh-format.md, plus leaf statistics).
nlohmann::json describeBvh(const tsah::FlatBvh& flat, const tsah::BvhBuildInfo& info);

// Loads and validates `path` (throws anim::ImportError naming the file) and prints its header on
// stdout: aligned text, or one JSON object when json is true.
void describeBvhFile(const std::string& path, bool json);

// The library's check that a tree was built for an animation (tsah/pipeline.hpp).
using tsah::checkTreeMatchesAnimation;

}  // namespace tsah::cli
