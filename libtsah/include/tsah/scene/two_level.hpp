#pragma once
// Two-level scenes (docs/two-level.md): a scene file kept as its distinct sources and instances
// instead of one baked animation. One bottom-level tree (BLAS) per source, built once in the
// source's own time; one top-level tree (TLAS) over the instances, optimized with the T-SAH cost
// over the scene's frames (the instances' world boxes along their paths are known ahead of time).
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "anim/scene.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/pipeline.hpp"

namespace tsah {

// One source's tree. Static sources (one keyframe): SAH + the insertion optimizer on that frame;
// animated sources: a T-SAH tree over their own keyframes, exactly as `tsah optimize` builds one
// for the source alone (optimizeAnimation).
struct Blas {
  uint32_t source = 0;     // index into SceneSources::sources
  bool animated = false;   // the source has two keyframes or more
  Bvh bvh;                 // boxes of its build frames
  FlatBvh flat;            // canonical form (what the runtimes trace)
  BvhBuildInfo info;       // its .tbvh header (optimizeAnimation's, for the source alone)
  std::vector<double> frameCosts;  // Eq. 1 at each build frame
  double cost = 0.0;               // C~^k over the build frames (static: the SAH cost)
};

// A distinct (animated source, time mapping): the instances showing it share its refitted boxes.
struct Pose {
  uint32_t blas = 0;
  anim::TimeMapping time;
};

// One top-level tree: the TLAS the runtimes refit and trace over `range` of the scene's time. A
// structure has one over the whole scene, or one per consecutive part (TlasOptions): the instances
// move, and a tree optimized for a shorter time keeps tighter boxes.
struct TlasTree {
  TimeRange range;          // where it is used (its info's time range); parts touch, no overlap
  uint32_t firstFrame = 0;  // its box sets: the scene frames firstFrame .. firstFrame + frameCount - 1,
  uint32_t frameCount = 0;  // those inside range, both ends included
  Bvh bvh;                  // over the instances' world boxes at those frames
  // Its .tbvh header: the build options, triangleCount = instances, vertexCount 0, topologyHash the
  // CRC-32 of the instances' source ids (u32 each), representativeFrames = frameCount.
  BvhBuildInfo info;
};

// How many top-level trees: `trees` of them, or with trees = 0 (auto) the fewest of 1, 2, 4, ...
// maxTrees over parts of equal frame counts whose average cost over the scene's frames is at most
// `budget` times that of a sweep-SAH TLAS rebuilt at each frame (rebuildTlas); past maxTrees, the
// cheapest built. At most one part per interval between scene frames. The parts start with equal
// frame counts; with searchBoundaries their boundaries are then searched with cheap stand-in trees
// and the searched parts' trees kept where they cost less on average than the even parts'
// (docs/two-level.md), so the result never costs more.
struct TlasOptions {
  uint32_t trees = 0;
  double budget = 1.1;
  uint32_t maxTrees = 32;
  bool searchBoundaries = true;
  static constexpr uint32_t kMaxTrees = 4096;
  // Throws tsah::ConfigError naming the field unless trees <= kMaxTrees, 1 <= maxTrees <= kMaxTrees
  // and budget is finite and >= 1.
  void validate() const;
};

// One step of buildTwoLevelScene and its wall time.
struct BuildPhase {
  std::string name;
  double seconds = 0.0;
};

struct TwoLevelScene {
  anim::SceneSources scene;           // sources, instances (world(t) = path(t) * placement), frames
  Objective objective;                // k, cT, cI, largest TLAS leaf
  std::vector<Blas> blases;           // one per source, blases[s].source == s
  std::vector<Pose> poses;            // of animated sources only
  std::vector<uint32_t> instancePose; // per instance: its pose, kInvalidIndex for a static source
  std::vector<double> frameTimes;     // the scene's frames (SceneSources::frameTimes)
  PrimitiveBoxes instanceBoxes;       // world box of every instance at every scene frame
  std::vector<TlasTree> tlases;       // in time order, covering [scene.start, scene.end]
  std::vector<double> tlasFrameCosts; // Eq. 1 at each scene frame, of the TLAS used there (tlasAt)
  double tlasCost = 0.0;              // C~^k over the scene frames
  // The rule of the trees of a tree set (treeIndexAt): a time on a boundary takes the later TLAS,
  // times outside the scene the first or the last.
  uint32_t tlasAt(double sceneTime) const;
  // Wall seconds of the build's steps in order: "blas" (every BLAS: initial tree and optimization;
  // each one's own time is its info.buildSeconds), "check" (validation and flattening of the BLAS),
  // "instances" (the instance boxes over the scene frames), "tlas" (every TLAS tried), "costs".
  std::vector<BuildPhase> buildPhases;

  uint32_t instanceCount() const { return static_cast<uint32_t>(scene.instances.size()); }
  const Blas& blasOf(uint32_t instance) const { return blases[scene.instances[instance].source]; }
  // Bytes of the trees: every BLAS (nodes, boxes of its build frames, primitive ids), the TLAS trees
  // (the same over their frames), and the instance table with its per-frame boxes.
  uint64_t blasBytes() const;
  uint64_t tlasBytes() const;
  uint64_t memoryBytes() const;
};

// The box of the 8 corners of `box` transformed by the affine `m` (empty stays empty).
Aabb transformBox(const Aabb& box, const anim::Matrix4& m);

// The box of a source's triangles at its own time `localTime` (the root box of its refitted BLAS).
Aabb sourceBox(const anim::Animation& source, double localTime);

// Instance `instance`'s world box at scene time t: its source's box at the instance's local time,
// transformed by world(t).
Aabb instanceWorldBox(const anim::SceneSources& scene, uint32_t instance, double sceneTime);

// Builds the two-level structure: options.method must be tsah (the BLAS of animated sources and
// the TLAS use options.objective's k; static BLAS use k = 0 on their single frame); options.frames
// representative frames per animated source; `tlas` how many top-level trees. Every tree is
// checked with tsah::validate. Throws tsah::ConfigError for other methods or invalid options,
// tsah::DataError for a source without triangles, tsah::Failure when a built tree is invalid.
TwoLevelScene buildTwoLevelScene(anim::SceneSources scene, const TreeOptions& options, const TlasOptions& tlas = {});
// loadSceneSources(path, load) then buildTwoLevelScene.
TwoLevelScene loadTwoLevelScene(const std::string& path, const anim::LoadOptions& load, const TreeOptions& options,
                                const TlasOptions& tlas = {});

// The two-level .tbvh file (version 3, docs/tbvh-format.md) of a structure: every BLAS, the TLAS
// and the instance and pose tables. save is atomic. Throws as encodeTwoLevelFile.
std::vector<uint8_t> encodeTwoLevelScene(const TwoLevelScene& twoLevel);
void saveTwoLevelScene(const std::string& path, const TwoLevelScene& twoLevel);
// Reads a version 3 file (decodeTwoLevelFile: tsah::FileError for a corrupt file) and checks it
// against the scene it was built for (the objects the file records as flattened are flattened
// first, anim::flattenObjects, unless `scene` is flattened so already): one BLAS per source with the source's triangles, vertices
// and topology hash, the instance table and poses the scene gives, the TLAS over the scene's
// frames with boxes that contain every instance's world box there; tsah::DataError ("TREE was not
// built for SCENE: ...") otherwise. The objective is the TLAS header's; costs are recomputed from
// the stored boxes.
TwoLevelScene loadTwoLevelSceneFile(const std::string& treePath, anim::SceneSources scene);
// The same for a file's bytes held in memory (encodeTwoLevelScene's), `treePath` naming them in
// the errors.
TwoLevelScene decodeTwoLevelScene(std::span<const uint8_t> bytes, const std::string& treePath, anim::SceneSources scene);

// The per-frame reference: a sweep-SAH TLAS over one frame's instance boxes (leaves of at most
// objective.maxLeafSize instances when that is not more expensive).
Bvh rebuildTlas(std::span<const Aabb> instanceBoxes, const Objective& objective);

}  // namespace tsah
