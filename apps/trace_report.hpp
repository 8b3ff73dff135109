#pragma once
// The statistics of `tsah trace` as one JSON object: the run (device, settings, "run_frames", the
// frame "range" [start, end) it covers), one entry per frame and their average; the text summary
// printed from it; and the merge of the objects of a run's chunks (`tsah report`), which gives the
// object of the whole run.
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "frame_runtime.hpp"
#include "tsah/render/renderer.hpp"

namespace tsah::cli {

struct FrameResult {
  uint32_t frame = 0;
  double time = 0.0;
  uint32_t tree = 0;  // of a tree set: the tree of the frame's part
  FrameUpdate update;
  RenderStats render;
  double frameMs = 0.0;  // the whole frame (FrameRender::frameMs): GPU passes overlap, so not their sum
  std::string image;     // the PNG written, if any
};

// One frame's entry ("tree" without a rebuild, "build_ms" with one) and back.
nlohmann::json frameJson(const FrameResult& r, bool rebuilds);
FrameResult frameFromJson(const nlohmann::json& j);

// Sets run["frames"] (ordered by frame) and run["average"]: times are means over frames, rates are
// total rays over total time per ray type. run["rebuild"] says whether frames rebuild.
void setFrames(nlohmann::json& run, std::vector<FrameResult> frames);

// The table of frames and averages that `tsah trace` prints, from the object.
void printTraceSummary(const nlohmann::json& run);

// The whole run from its chunks' objects ({file, object} each): refuses (DataError naming the
// file) objects of another run (a different animation, tree, image size, camera, seed, ... or
// frame count), overlapping ranges and missing frames. The run's description is the first chunk's;
// "images" only where every chunk wrote its PNGs into the same folder.
nlohmann::json mergeChunks(const std::vector<std::pair<std::string, nlohmann::json>>& chunks);

}  // namespace tsah::cli
