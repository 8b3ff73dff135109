#pragma once
// `--structure auto` (docs/two-level.md#the-structure-auto-chooses): per scene object, the estimated
// cost of keeping its instances as instances against that of its triangles flattened into the
// parent level, both relative to the scene's box.
#include <cstdint>
#include <string>
#include <vector>

#include "anim/scene.hpp"
#include "tsah/core/objective.hpp"

namespace tsah {

struct StructureChoiceOptions {
  CostModel cost;               // cT, cI of the estimates
  uint32_t maxLeafSize = 4;     // leaves of the estimating trees (the BLAS's)
  uint32_t frames = 4;          // representative scene frames (evenly spaced, the first and last among them)
  // The cost of entering an instance, per unit of its box's relative area: its box test (cI) and
  // the ray moved into its space and a BLAS traversal begun (two transforms and the reciprocal
  // direction: about two node tests, 2 cT). Negative: 2 cT + cI.
  double instanceCost = -1.0;
  // Flatten an object only when its flattened cost is at most (1 - margin) times its instanced
  // cost: flattened triangles are copies, refitted every frame when they move.
  double margin = 0.1;
  // Flatten no more triangles than this many times the triangles of the structure kept instanced
  // (every source once): the memory bound.
  double memoryFactor = 16.0;
  // When moving objects are flattened, the kept objects join them in one tree (the whole scene
  // flattened) only if their triangles, once per instance, are at most this many times the
  // flattened ones and the estimate favours it: that tree is optimized over every frame, where a
  // static BLAS is built once, so a large static environment stays instanced.
  double wholeSceneFactor = 1.0;
};

// The estimate's options for trees built with `objective`: its cT, cI and largest leaf.
inline StructureChoiceOptions structureChoiceOptions(const Objective& objective) {
  StructureChoiceOptions options;
  options.cost = objective.cost;
  options.maxLeafSize = objective.maxLeafSize;
  return options;
}

struct ObjectStructureChoice {
  uint32_t object = 0;
  std::string name;
  uint32_t instances = 0;
  bool moves = false;              // an animated source or a keyed path
  bool keyed = false;              // an instance moves along a keyed path
  // One instance without a keyed path: flattened whatever the estimate (as Cycles flattens
  // objects that are not instanced): its flattened triangles are no copy, and it moves (or not)
  // as its source does.
  bool single() const { return instances == 1 && !keyed; }
  uint64_t flattenedTriangles = 0; // its triangles once per instance
  // Average over the representative frames, relative to the scene's box (Eq. 1's scale): the SAH
  // cost of a tree over its instances' world boxes (cT per interior node, instanceCost per instance box)
  // plus each instance's BLAS cost (a binned SAH tree over its source at its local time) over its
  // transformed box; and the SAH cost of a binned SAH tree over its world triangles built at each
  // frame. Negative when not estimated (one instance without a path, the memory bound, or a
  // static object when a moving one is flattened: it stays instanced whatever its costs).
  double instancedCost = -1.0, flattenedCost = -1.0;
  bool flatten = false;
  std::string reason;
};

struct StructureChoice {
  std::vector<ObjectStructureChoice> objects;  // in the scene's object order
  std::vector<uint32_t> flattenedObjects;      // increasing
  uint32_t frames = 0;                          // representative frames used
  // When a moving object is flattened and others stay instanced: the estimated cost of the two
  // levels so decided (a tree over the kept instances and the flattened source, with their BLAS
  // costs) and of every object flattened into one tree, in the objects' scale. Negative when not
  // weighed (no moving object flattened, nothing or a moving object kept instanced, the whole
  // scene past the memory bound, or the kept triangles past wholeSceneFactor).
  double decidedCost = -1.0, wholeFlattenedCost = -1.0;
  double seconds = 0.0;                         // time of the estimate
  bool allFlattened() const { return flattenedObjects.size() == objects.size(); }
};

// The decision for every object of `scene` (not flattened yet). Objects of one instance without a
// keyed path are flattened; the others by the estimate. Objects that move are decided
// first; static objects are flattened only when no moving one is (the flattened objects share one
// source, and a moving one would refit the static triangles every frame). Among the objects the
// cost favours, the memory bound takes them by decreasing saving. When moving objects are
// flattened and only static ones kept (within wholeSceneFactor), every object is flattened (one
// tree) if its estimate is not above the two levels so decided. Throws tsah::ConfigError for a scene flattened
// already.
StructureChoice chooseObjectStructure(const anim::SceneSources& scene, const StructureChoiceOptions& options = {});

}  // namespace tsah
