#pragma once
// The GPU runtime of a two-level scene (docs/two-level.md), the device counterpart of
// tsah::TwoLevelRuntime. Uploaded once: every BLAS topology (triangle indices, slot vertex ids,
// parents and leaves; instances of one source share them), each source's keyframes, the static
// BLAS refitted once at their source's start time, one node/box array, positions and Woop triangles
// per pose, and (Config::tlas Refit) the T-SAH TLAS's nodes and topology. updateAt(t) runs one
// CUDA graph (captured at its first use, replayed after): the instances' transforms (computed on
// the host, 3x4 each) uploaded, each pose's positions at its local time (the flat runtime's
// interpolation kernel) and its BLAS refit and Woop pass, the instances' world boxes from their
// BLAS root boxes, and the TLAS refit (or, with Config::tlas a rebuild, a new TLAS built over those
// boxes). A frame whose poses all keep their local time replays a second graph without the BLAS
// work. Rays traverse the TLAS with the binary layout's device loop (Bvh2Traversal,
// bvh2_traversal.cuh); at a TLAS leaf the ray is moved into the instance's space and traced
// through the instance's BLAS by the same loop, as the CPU does, or (Config::layout cwbvh) by the
// compressed 8-wide layout's traversal (docs/cwbvh.md), each BLAS collapsed once at upload and
// refitted and re-quantized by the flat runtime's level kernels, all poses of a source in one
// launch per level. updateShutter blurs a frame as
// TwoLevelRuntime::updateShutter does, and the queries with per-ray times trace it
// (two_level_blur.hpp).
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include "tsah/core/aabb.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace tsah::cuda {

// How each updateAt brings the TLAS to the frame: the uploaded tree (the T-SAH TLAS) refitted
// over the instances' world boxes, or a new tree built over those boxes by a per-frame GPU
// rebuild (rebuild_types.hpp's LBVH or HLBVH-SAH, leaves of at most the objective's maxLeafSize
// instances, its cT and cI for the collapse).
enum class TlasUpdate { Refit, Lbvh, HlbvhSah };
const char* tlasUpdateName(TlasUpdate update);       // "refit", "lbvh", "hlbvh-sah"
TlasUpdate parseTlasUpdate(std::string_view name);   // throws tsah::ConfigError for anything else

namespace detail {
class EventTimer;
struct TwoLevelTraceAccess;
struct TwoLevelBlurAccess;
class TwoLevelBlur;
}

// Device time of one updateAt (CUDA events, milliseconds) and what it did.
struct TwoLevelUpdateTimings {
  double uploadMs = 0.0;  // the instance transforms and pose frames, host to device
  double blasMs = 0.0;    // the moved poses' interpolation, refit and Woop pass
  double tlasMs = 0.0;    // instance world boxes and the TLAS refit or rebuild
  double tlasRebuildMs = 0.0;  // the rebuild's part of tlasMs (its steps' events; 0 with a refit)
  uint32_t blasRefits = 0;  // poses refitted: those whose local time changed since the last update
  uint32_t instances = 0;
  uint32_t tlasNodes = 0;   // interior nodes of the TLAS (a rebuilt one: those reachable)
  double totalMs() const { return uploadMs + blasMs + tlasMs; }
};

class GpuTwoLevelRuntime {
 public:
  struct Config {
    int device = 0;
    // The BLAS layout: bvh2 (the binary layout) or cwbvh (compressed 8-wide; each source's tree
    // collapsed with the scene's objective, k 0 for a static one, as the CPU's wide BLAS). The
    // TLAS is binary in both. With cwbvh every pose is interpolated and refitted (blockRefits and
    // keyedPoses apply to bvh2 BLAS only). Anything else: tsah::ConfigError.
    Layout layout = Layout::Bvh2;
    // Refit the poses' BLAS and the TLAS by blocks walking in shared memory: each pose's tree split
    // into subtrees of at most refitPartLeaves leaves (one block each) and the top above them
    // (tsah::splitForBlockRefit), the TLAS as one part when it fits the device's opt-in shared
    // memory per block (15 * 4 bytes per interior node); false: the global-memory walk for every
    // tree (the reference; the boxes are the same bit for bit).
    bool blockRefits = true;
    uint32_t refitPartLeaves = 512;
    // Update the poses without a refit: each pose's boxes are lerped from its source's tree refitted
    // once at every keyframe, with the weights and rounding that lerp its vertices, so they hold
    // them (looser than a refit between keyframes, equal at a keyframe); one launch per source for
    // all its poses. Used for a source whose key boxes take at most keyedPoseBytes of device
    // memory (64 bytes per node and keyframe); the others, and every source when false, refit.
    bool keyedPoses = true;
    uint64_t keyedPoseBytes = uint64_t(256) << 20;
    TlasUpdate tlas = TlasUpdate::Refit;  // how each update brings the TLAS to the frame (above)
    // Time the update's phases (TwoLevelUpdateTimings' upload, BLAS and TLAS parts) by events
    // inside the frame's graph; false: only its start and end (two nodes fewer in the graph; the
    // whole update is then blasMs, uploadMs and tlasMs 0).
    bool phaseTimings = true;
  };

  // Keeps a reference to `scene` (it must outlive the runtime) and runs updateAt(first frame time).
  // Throws tsah::DataError for a tree deeper than the traversal stack or a source without keyframes;
  // updateAt throws tsah::Failure when a rebuilt TLAS is deeper than the traversal stack.
  GpuTwoLevelRuntime(const TwoLevelScene& scene, Config config);
  explicit GpuTwoLevelRuntime(const TwoLevelScene& scene) : GpuTwoLevelRuntime(scene, Config{}) {}
  ~GpuTwoLevelRuntime();
  GpuTwoLevelRuntime(const GpuTwoLevelRuntime&) = delete;
  GpuTwoLevelRuntime& operator=(const GpuTwoLevelRuntime&) = delete;

  // The scene at time t, on the device (synchronizes to read the timings).
  TwoLevelUpdateTimings updateAt(double sceneTime);
  double time() const;
  uint64_t blasRefits() const;  // in all, the static BLAS' refits at construction included
  uint64_t keyBoxBytes() const;  // device memory of the keyed poses' key boxes (Config::keyedPoses)

  // Batch queries of host rays (closest hit: instance, triangle of its source, t; any hit).
  std::vector<TwoLevelHit> closestHits(std::span<const Ray> rays, RayPassStats* stats = nullptr);
  std::vector<uint8_t> anyHits(std::span<const Ray> rays, RayPassStats* stats = nullptr);

  // Motion blur (docs/motion-blur.md, "Two-level scenes"): TwoLevelRuntime::updateShutter's frame on
  // the device, with its keys (open, every scene frame strictly inside, close), key matrices, key
  // boxes and contract: one key, or a shutter in which no instance's float matrix and no pose's local
  // time changes, is updateAt(open) (not blurred). Per key the moving poses' BLAS interpolated and
  // refitted on the device and built into the flat blurred runtime's layout, the instances' key boxes
  // (instanceKeyBox) and the T-SAH TLAS refitted from them (whatever Config::tlas: the instant frames'
  // rebuilds are not used for a blurred one). The instant state is updateAt(close)'s: the queries
  // without times and the renderer see the close. Throws tsah::ConfigError for an open or close that
  // is not finite or open > close. updateAt ends a blurred frame.
  void updateShutter(double openTime, double closeTime);
  bool blurred() const;
  std::span<const float> keyTimes() const;  // shutter fractions (first 0, last 1); empty when not blurred
  // The instances' boxes at key k of a blurred frame (the TLAS at key k's leaves; tsah::ConfigError
  // when not blurred or k is out of range).
  std::vector<Aabb> keyInstanceBoxes(std::size_t key) const;
  // The rays at shutter fractions times[i] (one per ray; outside [0, 1]: the nearer end), as
  // TwoLevelRuntime::closestHit(ray, time) / anyHit(ray, time); not blurred: the instant queries.
  // Throws tsah::ConfigError when the counts differ.
  std::vector<TwoLevelHit> closestHits(std::span<const Ray> rays, std::span<const float> times,
                                       RayPassStats* stats = nullptr);
  std::vector<uint8_t> anyHits(std::span<const Ray> rays, std::span<const float> times, RayPassStats* stats = nullptr);

  // Device arrays (docs/cuda-runtime.md#device-arrays), as GpuRuntime's: rays in the caller's device
  // memory (GpuRuntime::DeviceRays), results written into the caller's device arrays, on the
  // runtime's stream ordered after the work queued on `stream` before the call and before the work
  // queued there after it; nothing waits for the device. Closest hits: one value per ray in each
  // non-null array, t, u, v (float), instance and triangle (uint32: the instance hit and the
  // triangle of its source); a miss writes t = +inf, u = v = 0 and both ids tsah::kNoHit.
  // occluded: one byte per ray, 1 when something is hit within (tmin, tmax). Times: each ray's
  // shutter fraction in the caller's device memory (one float per ray) or, when null, `value` for
  // every ray, as closestHits(rays, times); not blurred: the instant queries. Throws
  // tsah::ConfigError for a null ray array, more than 2^32 - 1 rays, a bad scalar limit, or a pointer
  // that is not device memory of the runtime's device.
  using StreamHandle = GpuRuntime::StreamHandle;
  struct DeviceHits {
    float* t = nullptr;
    float* u = nullptr;
    float* v = nullptr;
    uint32_t* instance = nullptr;
    uint32_t* triangle = nullptr;
  };
  struct DeviceTimes {
    const float* times = nullptr;
    float value = 0.0f;
  };
  void closestHitsOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceHits& hits, StreamHandle stream = nullptr);
  void closestHitsOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceTimes& times, const DeviceHits& hits,
                           StreamHandle stream = nullptr);
  void anyHitsOnDevice(const GpuRuntime::DeviceRays& rays, uint8_t* occluded, StreamHandle stream = nullptr);
  void anyHitsOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceTimes& times, uint8_t* occluded,
                       StreamHandle stream = nullptr);

  // Host copies of the current state: the instances' world boxes, and the TLAS traced now (the
  // refitted one or this frame's rebuilt one) in canonical form with this frame's node boxes
  // (frameCount 1; triIndex: slot -> instance); a pose's BLAS (scene().poses[pose]) with the node and
  // root boxes of this instant frame.
  std::vector<Aabb> downloadInstanceBoxes() const;
  FlatBvh downloadTlas() const;
  FlatBvh downloadPoseTree(uint32_t pose) const;  // bvh2 BLAS (tsah::ConfigError for cwbvh)
  // Config::layout cwbvh: a pose's BLAS in the compressed layout with this frame's nodes and root
  // box (tsah::ConfigError for bvh2).
  CwbvhTree downloadPoseCwbvh(uint32_t pose) const;
  const DeviceInfo& device() const;
  const TwoLevelScene& scene() const;

  struct Impl;

 private:
  friend class GpuTwoLevelRenderer;  // gpu_two_level_render.hpp: traces the current frame's device state
  detail::TwoLevelTraceAccess traceAccess() const;
  detail::TwoLevelBlurAccess blurAccess();  // what updateShutter builds a blurred frame from
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<detail::TwoLevelBlur> blur_;  // the blurred frame (two_level_blur.cpp)
  // The device-array queries' ordering with the caller's stream (two_level_device_arrays.cpp).
  std::unique_ptr<detail::EventTimer> callerFences_;
  template <bool AnyHit>
  void traceOnDevice(const GpuRuntime::DeviceRays& rays, const DeviceTimes* times, const DeviceHits& hits,
                     uint8_t* occluded, StreamHandle stream);
};

}  // namespace tsah::cuda
