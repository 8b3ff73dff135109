#pragma once
// `tsah export --boxes OUT.ply|OUT.obj`: the tree's boxes at one frame as a mesh for a viewer
// (tsah/box_view.hpp builds it). The options live here so that cmd_export.cpp only hooks them in.
#include <CLI/CLI.hpp>
#include <memory>
#include <span>
#include <string>

#include "anim/animation.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/layout/flat_bvh.hpp"

namespace tsah::cli {

struct BoxExportOptions {
  bool enabled = false;
  std::string style = "bars", colour = "depth";
  uint32_t minDepth = 0, maxDepth = 1000000;
  double minShare = 0.0;  // percent of the frame's cost
  double minGrowth = 0.0;
  float barWidth = 0.0f;
  uint32_t growthFrames = 50;
  bool withMesh = false;
};

// Adds --boxes and its options to `export`; the returned object is filled when the command parses.
std::shared_ptr<BoxExportOptions> addBoxExportOptions(CLI::App& exportCommand);

// Writes the box view of the tree at `time` (positions: the animation's vertices then) to `out`
// (.ply, or .obj with a .mtl beside it), atomically, and prints one summary line.
void exportBoxes(const BoxExportOptions& options, const tsah::FlatBvh& flat, const tsah::BvhBuildInfo& info,
                 const anim::Animation& animation, double time, std::span<const float> positions,
                 const std::string& out);

}  // namespace tsah::cli
