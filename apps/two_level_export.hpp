#pragma once
// `tsah export TREE SCENE -o OUT` of a version 3 tree (a two-level scene, docs/two-level.md): the
// renderer buffers of one scene time, every BLAS view (a static source's, or a pose's refitted at
// its local time) in the chosen layout, the binary TLAS refitted at that time, the instance table
// with each instance's world matrix and its inverse, and the C header describing them
// (docs/two-level.md#exported-buffers).
#include <cmath>
#include <string>

#include "tsah/runtime/cpu_runtime.hpp"

namespace tsah::cli {

struct TwoLevelExport {
  std::string tree, scene, out;
  int frame = -1;               // a scene frame (SceneSources::frameTimes), or -1 with `time`
  double time = std::nan("");  // the scene time; NaN: the frame (default 0)
  Layout layout = Layout::Bvh2;
  unsigned threads = 0;
};

// Loads TREE with SCENE (loadTwoLevelSceneFile: the file must have been built for that scene),
// runs a TwoLevelRuntime at the export time and writes OUT's files all or none. Prints one line.
void exportTwoLevel(const TwoLevelExport& request);

}  // namespace tsah::cli
