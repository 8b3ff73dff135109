#pragma once
// The GPU runtime's small shared types (gpu_runtime.hpp is the front door): the per-frame rebuild
// baselines' options and their timings. (The layout a tree is traced in is tsah::Layout, Bvh2 or
// Cwbvh on the GPU: core/kinds.hpp.)
#include <cstdint>
#include <string_view>

#include "tsah/core/cost.hpp"
#include "tsah/core/kinds.hpp"

namespace tsah::cuda {

enum class RebuildMethod { Lbvh, HlbvhSah };
const char* rebuildMethodName(RebuildMethod method);  // "lbvh", "hlbvh-sah"
RebuildMethod parseRebuildMethod(std::string_view name);  // throws tsah::ConfigError for anything else

struct RebuildOptions {
  RebuildMethod method = RebuildMethod::Lbvh;
  // Leaf collapse with LeafCollapser's rule for one frame (k = 0): bottom-up, a subtree of at most
  // maxLeafSize triangles becomes one leaf when cI * n * area <= its cost as it is. false: one
  // triangle per leaf (the "bare" build).
  bool collapse = true;
  uint32_t maxLeafSize = 8;
  CostModel cost;
  // Woop triangles of the new tree (tracing needs them; false only to time the bare build).
  bool woop = true;
  // Layout cwbvh: binary subtrees of at most this many triangles (in one slot range) become one
  // leaf of the compressed tree (0 or 1: only the binary leaves, the default; at most 8).
  uint32_t wideMergeTriangles = 0;
};

// Device time of one rebuild, in milliseconds (CUDA events), and what was built.
struct RebuildTimings {
  double interpolateMs = 0.0;  // rebuildAt: positions of the frame (rebuild(positions): upload)
  double mortonMs = 0.0;       // triangle boxes (a build over boxes: read), centroid bounds, Morton codes
  double sortMs = 0.0;         // CUB radix sort of the 30-bit codes
  double hierarchyMs = 0.0;    // Karras radix tree (HLBVH-SAH: and the 15-bit clusters)
  double topMs = 0.0;          // HLBVH-SAH: SAH tree over the clusters, reordering of the triangles
  double bottomUpMs = 0.0;     // boxes bottom-up (and the collapse), GpuBvhNode output
  double wideMs = 0.0;         // layout cwbvh: the conversion into the compressed 8-wide layout
  double woopMs = 0.0;
  uint32_t clusters = 0;       // HLBVH-SAH only
  uint32_t interiorNodes = 0, leaves = 0, depth = 0;  // of the binary tree
  uint32_t wideNodes = 0;      // layout cwbvh: nodes of the compressed tree
  uint32_t wideLevels = 0;     // layout cwbvh: its levels (the conversion's steps; = CwbvhTree::depth)
  // The binary tree without interpolation and Woop (the "bare build" when collapse is off).
  double buildMs() const { return mortonMs + sortMs + hierarchyMs + topMs + bottomUpMs; }
  // Everything until the traced tree is ready: with layout cwbvh the conversion counts too.
  double totalMs() const { return interpolateMs + buildMs() + wideMs + woopMs; }
};

}  // namespace tsah::cuda
