#pragma once
// The CPU runtime of a two-level scene (docs/two-level.md): a binary TLAS over BLAS runtimes in
// any CPU layout (bvh2, bvh4, bvh8). Per frame (update(t)):
// each pose's positions at its local time and its BLAS refit (static BLAS are refitted once, at
// construction; a pose whose local time did not change is not refitted), the instances' world
// matrices and inverses at t, then the TLAS refitted (or rebuilt, the per-frame reference) from the
// instances' world boxes. Rays are traced through the TLAS; at a TLAS leaf the ray is moved into
// the instance's space (origin by the inverse affine transform, direction by its linear part, not
// normalized, so t is the world ray's parameter) and traced by the instance's BLAS runtime
// (CpuRuntime::closestHit / anyHit: the same traversal and watertight triangle test as a single
// tree); the TLAS itself is traced by the binary traversal loop (detail::traverse), or with bvh4 /
// bvh8 BLAS by the wide kernels over the TLAS collapsed to that width (instances as leaf children).
// Motion blur (updateShutter, docs/motion-blur.md "Two-level scenes"): the instances' world matrices
// and the poses' BLAS at every key of a shutter, the TLAS refitted at every key, and rays traced at
// their own time (two_level_motion.cpp).
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "tsah/core/instance_transform.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/scene/two_level.hpp"

namespace tsah {

namespace detail {
struct TlasKeys;  // two_level_frame.hpp: the blurred TLAS at one ray's time
}

// A hit of a two-level scene: the instance and the triangle of its source.
struct TwoLevelHit {
  float t = 0.0f, u = 0.0f, v = 0.0f;
  uint32_t instance = kNoHit;
  uint32_t prim = kNoHit;  // triangle id in the instance's source
  bool valid() const { return instance != kNoHit; }
};

// The inverse of an affine (invertible) transform, in double.
anim::Matrix4 inverseAffine(const anim::Matrix4& m);
// World -> instance space of an instance placed by `world` (the inverse, rounded to float), or none
// when world's linear part is singular or not finite: a path that scales through 0 flattens the
// instance for an instant, and its triangles are then never hit (as the flat scene's degenerate ones).
std::optional<Affine3x4> instanceSpace(const anim::Matrix4& world);

// An instance's box at one key of a blurred frame: the key's instance -> world map applied to the 8
// corners of `local` (the union of the instance's BLAS root boxes over every key of the shutter),
// rounded outward, each side widened by motion::lerpPad of its row's magnitude bound, so that the
// lerp of two keys' boxes (motion::lerpBox) holds the lerped map times the lerped vertex in float
// (docs/motion-blur.md, "Two-level scenes"). An empty box stays empty.
Aabb instanceKeyBox(const Aabb& local, const Affine3x4& toWorld);

// Each pose's local time (scene.poses' order) at each of `times` (scene times): [pose][time].
std::vector<std::vector<double>> poseLocalTimes(const TwoLevelScene& scene, std::span<const double> times);

// What moves over a shutter's keys (scene times), where the CPU's and the GPU's updateShutter start:
// per key k and instance i its world matrix rounded to float (toWorld[k * instances + i]), whether
// an instance's float matrix differs between keys, each pose's local time at each key and whether
// it differs between keys; anyMoves: an instance or a pose does.
struct ShutterMotion {
  std::vector<Affine3x4> toWorld;
  std::vector<uint8_t> movingInstances;
  std::vector<std::vector<double>> poseLocal;  // [pose][key]
  std::vector<uint8_t> movingPoses;
  bool anyMoves = false;
};
ShutterMotion shutterMotion(const TwoLevelScene& scene, std::span<const double> keys);

class TwoLevelRuntime {
 public:
  enum class TlasUpdate { Refit, Rebuild };
  struct Config {
    uint32_t threads = 0;  // 0: one per hardware thread
    TlasUpdate tlas = TlasUpdate::Refit;
    // The BLAS layout: bvh2, or bvh4 / bvh8 collapsed once per BLAS runtime with the scene's
    // objective (CpuRuntime's wide layouts and SIMD kernels). The TLAS is binary (tlas()); with a
    // wide BLAS layout the instant frame traces it collapsed to the same width, each instance a leaf
    // child of its own, with the same SIMD node test (docs/two-level.md).
    Layout layout = Layout::Bvh2;
    // With a wide layout, how the poses' BLAS hold their triangles (TriangleForm): Vertices, the
    // default, refits a pose without computing Woop rows, the bulk of a pose's refit, and traces
    // its triangles with the watertight test on their vertices; Woop keeps Woop packets (what
    // `tsah export` writes). Static BLAS, refitted once, always hold Woop packets.
    TriangleForm poseTriangles = TriangleForm::Vertices;
  };

  // Keeps a reference to `scene` (it must outlive the runtime). Refits every static BLAS once and
  // runs update(first frame time). Throws tsah::DataError for a tree the runtimes refuse
  // (CpuRuntime's checks).
  TwoLevelRuntime(const TwoLevelScene& scene, Config config);
  explicit TwoLevelRuntime(const TwoLevelScene& scene) : TwoLevelRuntime(scene, Config{}) {}
  ~TwoLevelRuntime();
  TwoLevelRuntime(const TwoLevelRuntime&) = delete;
  TwoLevelRuntime& operator=(const TwoLevelRuntime&) = delete;

  // The form the poses' BLAS hold their triangles in: Config::poseTriangles in bvh4 / bvh8, Woop
  // in bvh2 (its only form). Static BLAS are always Woop.
  TriangleForm poseTriangles() const {
    return config_.layout == Layout::Bvh2 ? TriangleForm::Woop : config_.poseTriangles;
  }

  // The scene at time t: poses whose local time changed refitted, world transforms, the TLAS of
  // the time's part (TwoLevelScene::tlasAt) refitted. Ends a blurred frame.
  void update(double sceneTime);

  // Motion blur over the shutter [open, close] (scene times; docs/motion-blur.md, "Two-level
  // scenes"). Keys: open, every scene frame strictly inside, close (motion::shutterKeys); per key
  // the instances' world matrices (rounded to float) and every pose's positions at its local time
  // (the pose's CpuRuntime::updateShutter with the same key fractions; a pose whose local time is
  // the same at every key is refitted once, instant); per key the instances' boxes (each key's
  // matrix applied to the union of the BLAS's root boxes over all keys, widened for rounding) and
  // the TLAS of the close's part refitted from them (TlasUpdate::Rebuild: rebuilt from the open's
  // boxes first). One key (open == close), or a shutter in which no instance's matrix and no
  // pose's local time changes, is update(open): not blurred. Throws tsah::ConfigError for an open or close that is not finite
  // or open > close; CpuRuntime::updateShutter's errors otherwise. time() is then close, and
  // instanceBoxes() and tlas() hold the last key's boxes.
  void updateShutter(double openTime, double closeTime);
  // True after an updateShutter that blurred (until update()).
  bool blurred() const { return !keyTimes_.empty(); }
  // The keys' shutter fractions (first 0, last 1) and scene times; empty when not blurred.
  std::span<const float> keyTimes() const { return keyTimes_; }
  std::span<const double> keySceneTimes() const { return keySceneTimes_; }
  // Instance `instance`'s box at key k < keyTimes().size() (what the TLAS at key k was refitted from).
  std::span<const Aabb> keyInstanceBoxes(std::size_t key) const;
  // Instance -> world at shutter fraction `time` as the blurred trace uses it: the key matrices (in
  // float) lerped entry by entry (motion::lerp) in the time's segment. Not blurred: world(time()) in float.
  Affine3x4 toWorldAt(uint32_t instance, float time) const;
  // Nearest hit / any hit at the ray's time, a shutter fraction in [0, 1] (outside: the nearer
  // end); not blurred: closestHit(ray) / anyHit(ray, order).
  TwoLevelHit closestHit(const Ray& ray, float time) const;
  bool anyHit(const Ray& ray, float time, AnyHitOrder order = AnyHitOrder::FarthestFirst) const;

  TwoLevelHit closestHit(const Ray& ray) const;
  // order: the BLAS traversals' child order (CpuRuntime::anyHit; the answer is the same).
  bool anyHit(const Ray& ray, AnyHitOrder order = AnyHitOrder::FarthestFirst) const;

  // BLAS refits: by the last update(), and in all (construction's static refits included).
  uint32_t lastUpdateBlasRefits() const { return lastRefits_; }
  uint64_t blasRefits() const { return totalRefits_; }
  double time() const { return time_; }
  const TwoLevelScene& scene() const { return scene_; }
  // The threads its updates and parallelFor run on (Config::threads, capped at the hardware's).
  uint32_t threadCount() const;
  // Runs body over [0, n) in chunks of at least `grain` on the runtime's threads (the renderer's passes).
  void parallelFor(std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body) const;

  // The instances' world boxes at the current time, and the TLAS in canonical form (the current
  // part's, its node boxes those of the current time; slots hold instance ids). An instance whose
  // world transform is singular (a path scale passing through 0) has no area at that time and is
  // never hit.
  std::span<const Aabb> instanceBoxes() const { return instanceBoxes_; }
  const FlatBvh& tlas() const { return tlas_; }
  // The BLAS runtime an instance traces (its pose's, or its static source's).
  const CpuRuntime& blasOf(uint32_t instance) const;
  // Bytes the runtime holds: every BLAS runtime's tree, triangles and positions, the TLAS, the
  // instance transforms and boxes.
  uint64_t memoryBytes() const;

 private:
  void refitTlas();
  void refitWideTlas();
  void selectTlas(double sceneTime);  // Refit: the TLAS of the time's part (TwoLevelScene::tlasAt) as tlas_
  const CpuRuntime& runtimeOf(uint32_t instance) const;
  void clearShutter();
  detail::TlasKeys keysAt(float time) const;  // the blurred frame's keys of the time's segment
  // The poses' positions at `local` (one local time per pose) refitted, only where it changed.
  void refitPoses(const std::vector<double>& local);

  const TwoLevelScene& scene_;
  Config config_;
  struct Pool;
  std::unique_ptr<Pool> pool_;
  std::vector<std::unique_ptr<CpuRuntime>> staticBlas_;  // per BLAS: null for animated sources
  std::vector<std::unique_ptr<CpuRuntime>> poses_;       // per pose
  std::vector<double> poseLocalTime_;                    // local time of each pose's last refit
  std::vector<std::vector<float>> poseScratch_;
  std::vector<Affine3x4> toInstance_;                    // per instance: world -> instance space
  std::vector<uint8_t> visible_;                         // per instance: world transform invertible now
  std::vector<Aabb> instanceBoxes_;
  std::vector<const CpuRuntime*> blas_;                  // per instance: the BLAS runtime it traces
  FlatBvh tlas_;                  // the TLAS traced now: a copy of the current part's, or rebuilt
  std::vector<FlatBvh> tlasTrees_;  // Refit: every part's TLAS topology (TwoLevelScene::tlases)
  uint32_t tlasPart_ = kInvalidIndex;
  // Wide BLAS layouts: tlas_'s topology in the BLAS's width, the instant frame's trace (wide_tlas.hpp).
  struct WideTop;
  std::unique_ptr<WideTop> wideTop_;
  double time_ = 0.0;
  // Motion blur (empty when not blurred): key fractions and scene times; per key, the instances'
  // world matrices in float and boxes, and the TLAS's interior nodes and root box; per instance
  // whether its matrix differs between keys (a still one traces with toInstance_).
  std::vector<float> keyTimes_;
  std::vector<double> keySceneTimes_;
  std::vector<Affine3x4> keyToWorld_;
  std::vector<Aabb> keyInstanceBoxes_;
  std::vector<GpuBvhNode> keyTlasNodes_;
  std::vector<Aabb> keyTlasRootBoxes_;
  std::vector<uint8_t> moving_;
  uint32_t lastRefits_ = 0;
  uint64_t totalRefits_ = 0;
};

}  // namespace tsah
