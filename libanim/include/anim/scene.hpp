#pragma once
// Scenes: objects (any input anim::load reads) placed, keyed along paths, time-mapped, instanced
// and optionally subdivided, baked into one Animation whose static vertices are stored once.
// The file format (JSON) is documented in docs/scenes.md.
#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "anim/animation.hpp"
#include "anim/load_options.hpp"

namespace anim {

// An affine 4x4 transform, row-major (m[4 * row + col]); the last row is 0 0 0 1.
using Matrix4 = std::array<double, 16>;
Matrix4 identityMatrix();
Matrix4 multiply(const Matrix4& a, const Matrix4& b);
// translate * rotate (Z after Y after X, degrees) * scale.
Matrix4 trsMatrix(const std::array<double, 3>& translate, const std::array<double, 3>& rotateDegrees,
                  const std::array<double, 3>& scale);
// Determinant of the linear (upper-left 3x3) part.
double linearDeterminant(const Matrix4& m);
// out = m * p for every point of `points` (x y z triples), in place.
void transformPoints(const Matrix4& m, float* points, std::size_t count);

// One key of a path (root motion): a transform at a scene time; between keys every component is
// interpolated linearly, outside the keys the first / last key holds.
struct TransformKey {
  double time = 0.0;
  std::array<double, 3> translate{0, 0, 0};
  std::array<double, 3> rotateDegrees{0, 0, 0};
  std::array<double, 3> scale{1, 1, 1};
};
Matrix4 pathMatrix(const std::vector<TransformKey>& path, double t);  // identity for an empty path

// Scene time t -> the object's own time: start + (t - offset) * speed, then outside the object's
// [start, end]: hold (clamp) or loop (wrap around).
enum class OutsideRange { Hold, Loop };
struct TimeMapping {
  double offset = 0.0;
  double speed = 1.0;
  OutsideRange outside = OutsideRange::Hold;
  double localTime(double sceneTime, double start, double end) const;
};

// One placement of an object: world(t) = pathMatrix(path, t) * placement.
struct SceneInstance {
  Matrix4 placement = identityMatrix();
  std::vector<TransformKey> path;
  TimeMapping time;
  bool keyed() const { return path.size() > 1; }
};

struct SceneObject {
  std::string name;
  std::string file;         // resolved: relative to the scene file's folder, data: paths resolved
  double fps = 0.0;         // the object's own sampling rate (LoadOptions::fps); 0: the scene's options
  std::string clip;         // LoadOptions::clip
  uint32_t subdivide = 0;   // uniform Loop subdivision levels (static triangle meshes only)
  std::vector<SceneInstance> instances;
};

struct SceneDescription {
  std::string file;         // the scene file
  std::string name;
  double fps = 30.0;        // bake rate (LoadOptions::fps overrides it)
  bool hasTimeRange = false;
  double start = 0.0, end = 0.0;
  std::vector<SceneObject> objects;
};

// True when `path` is a JSON file holding an object with an "objects" member (a scene, not a
// frame manifest).
bool isSceneFile(const std::string& path);

// Scenes' "data:REL" paths (docs/scenes.md) name files inside the data folder and nothing else.
// checkDataPath throws tsah::DataError when REL is empty or absolute or has a ".." part;
// requireInsideDataFolder throws tsah::DataError when `path`, its symbolic links resolved, is not
// inside `folder` (the data folder, or an archive of it unpacked into the cache), links resolved too.
void checkDataPath(const std::string& rel);
void requireInsideDataFolder(const std::filesystem::path& folder, const std::filesystem::path& path,
                             const std::string& rel);

// Reads and checks a scene file (transforms finite and invertible, speeds >= 0, keys increasing,
// files resolved). Throws tsah::FileError naming the scene file and the object.
SceneDescription parseScene(const std::string& path, const LoadOptions& options = {});

// A scene's triangles and vertices counted from its description, before anything is baked: every
// object's instances, nested scene files counted the same way (each file once, however often it
// is used), subdivision levels applied. Object files that are not scenes are loaded to count them;
// one that cannot be read counts as empty (the bake reports it). Saturates at 2^64 - 1.
struct SceneSize {
  uint64_t triangles = 0, vertices = 0;
};
SceneSize describedSceneSize(const std::string& path, const LoadOptions& options = {});

// What each object contributes (all its instances together).
struct SceneObjectReport {
  std::string name, file;
  uint32_t instances = 0;
  uint32_t sourceTriangles = 0, sourceVertices = 0, sourceKeyframes = 0;  // one instance, after subdivision
  uint32_t subdivisionLevels = 0;
  uint64_t triangles = 0, vertices = 0, movingVertices = 0;                 // all instances
};

// The memory statement, made before anything scene-sized is allocated.
struct SceneStatement {
  uint64_t triangles = 0, vertices = 0, movingVertices = 0, keyframes = 0;
  uint64_t animationBytes = 0;  // the baked Animation (Animation::memoryBytesFor)
  uint64_t sourceBytes = 0;     // the loaded (and subdivided) objects, each held once
  uint64_t peakBytes = 0;       // animation + sources + bake scratch: what the bake needs at most
  uint64_t availableBytes = 0;  // this machine's available memory when the statement was made
};

struct BakedScene {
  Animation animation;
  SceneDescription description;
  std::vector<SceneObjectReport> objects;
  SceneStatement statement;
  uint32_t distinctSources = 0;  // objects loaded (instances and repeated files share one)
};

// A scene loaded without baking: each distinct source once, in its own time, and every instance
// as (source, world transform over time, time mapping). bakeScene bakes exactly this. An object
// that is itself a scene file is one source (that scene baked, anim::load).
struct SceneSourceInstance {
  uint32_t object = 0;   // index into SceneDescription::objects
  uint32_t source = 0;   // index into SceneSources::sources
  Matrix4 placement = identityMatrix();
  std::vector<TransformKey> path;
  TimeMapping time;
  bool keyed() const { return path.size() > 1; }
  Matrix4 worldAt(double sceneTime) const { return multiply(pathMatrix(path, sceneTime), placement); }
  // The source's own time shown at sceneTime.
  double localTime(double sceneTime, const Animation& animation) const {
    return time.localTime(sceneTime, animation.startTime(), animation.endTime());
  }
};

// A run of an instance's source triangles and where the scene file's bake puts them: triangles
// sourceFirst .. sourceFirst + count - 1 of instance `instance` are triangles 0 .. count - 1 of the
// scene file's instance `originalInstance` (bake order) of object `object`, baked triangles
// bakedFirst ...
struct SceneTriangleRun {
  uint32_t instance = 0, sourceFirst = 0, count = 0;
  uint32_t object = 0, originalInstance = 0, bakedFirst = 0;
};

struct SceneSources {
  SceneDescription description;
  std::vector<std::shared_ptr<const Animation>> sources;  // distinct (file, fps, clip, subdivision)
  std::vector<uint32_t> objectSource;                     // per object: its source
  // Every instance in bake order: objects in file order, each object's instances in order; the
  // baked animation holds instance i's triangles after those of instances 0..i-1.
  std::vector<SceneSourceInstance> instances;
  uint64_t sourceBytes = 0;  // the loaded (and subdivided) sources
  double start = 0.0, end = 0.0, fps = 30.0;  // the scene's time range and frame rate
  uint64_t frameCount = 1;                    // keyframes of the bake (< 2^32)
  // Objects flattened into one source (flattenObjects), increasing; empty when none.
  std::vector<uint32_t> flattenedObjects;
  // Every instance's triangles mapped back to the scene file's instances and bake, sorted by
  // (instance, sourceFirst): one run per instance, several for the instance flattenObjects made.
  std::vector<SceneTriangleRun> triangleRuns;

  const Animation& sourceOf(const SceneSourceInstance& instance) const { return *sources[instance.source]; }
  // The bake's keyframe times: start, every 1/fps after it below end, and end.
  std::vector<double> frameTimes() const;
  // The run holding triangle `prim` of instance `instance`'s source; bakedTriangle: that
  // triangle's id in bakeScene's animation of the scene file, whatever was flattened.
  const SceneTriangleRun& runOf(uint32_t instance, uint32_t prim) const;
  uint32_t bakedTriangle(uint32_t instance, uint32_t prim) const;
};

// Parses the scene and loads every distinct source once (the checks and errors of bakeScene's
// loading: missing files, cycles, subdivision limits, more than 2^32 keyframes).
SceneSources loadSceneSources(const std::string& path, const LoadOptions& options = {});

// The objects `objects` (increasing ids of description.objects) flattened into their parent level:
// every instance of them baked together, as bakeScene bakes them (world-space triangles, keyframes
// at the scene's frames; one keyframe when none of them moves), into one source appended after the
// sources still shown, and shown by one instance appended after the others (identity placement, no
// path, the identity time map; its object the first flattened one). Sources no other instance
// shows are dropped; triangleRuns map the new instance's triangles back to the flattened ones.
// Nothing is flattened for an empty list. Throws tsah::ConfigError for ids out of range, not
// increasing, or a scene flattened already; tsah::DataError naming the scene file when the baked
// source would pass 2^32 triangles or vertices or not fit in the available memory.
SceneSources flattenObjects(SceneSources scene, const std::vector<uint32_t>& objects);

// Loads every object once (loadSceneSources), states the memory, refuses (tsah::FileError naming the scene and the object
// that crosses the line) a scene that would not fit, then bakes keyframes at the scene's rate (or
// options.fps) over its time range.
BakedScene bakeScene(const std::string& path, const LoadOptions& options = {});
// bakeScene(path, options).animation: what anim::load returns for a scene file.
Animation loadScene(const std::string& path, const LoadOptions& options = {});

}  // namespace anim
