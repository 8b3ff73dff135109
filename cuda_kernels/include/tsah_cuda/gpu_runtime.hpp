#pragma once
// The GPU runtime: the CUDA counterpart of tsah::CpuRuntime + tsah::renderFrame.
//
// The animation's topology and ALL of its keyframes are uploaded once. Per frame, on the device:
//   updateAt(t):  vertex interpolation between the two neighbouring keyframes (anim::Animation::
//                 positionsAt's formula), bottom-up refit of the uploaded tree (atomic counter per
//                 node), Woop triangles;
//   rebuildAt(t): the per-frame rebuild baselines instead of the refit: LBVH (30-bit Morton codes,
//                 Karras 2012; the paper's HLBVH-med) or HLBVH-SAH (SAH over the clusters of the top
//                 15 Morton bits, spatial median below), then leaf collapse (<= 8 triangles), with
//                 layout cwbvh the conversion into the compressed 8-wide layout, and Woop;
//   renderFrameGpu: primary (closest hit), ambient-occlusion and shadow rays (any hit) with the
//                 CPU renderer's random numbers and shading; a blurred frame (updateShutter) at
//                 each pixel's shutter time, as the CPU renderer.
// Every phase is timed with CUDA events. Positions, boxes and Woop triangles of updateAt are
// bit-identical to the CPU runtime's; hits agree up to ties between triangles at equal distance.
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include "anim/animation.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/core/cost.hpp"
#include "tsah/core/objective.hpp"
#include "tsah/layout/blurred_node.hpp"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/layout/cwbvh_layout.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/render/image.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/layout/woop.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/rebuild_types.hpp"

namespace tsah::cuda {

// Device time of one refit update, in milliseconds (CUDA events).
struct UpdateTimings {
  double interpolateMs = 0.0;  // update(positions): the upload instead
  double refitMs = 0.0;  // the refit (and re-quantization)
  double woopMs = 0.0;   // the Woop pass, which runs beside the refit: only the part after the refit ends
  // Triangles whose Woop form (and leaf boxes) the update recomputed: all of them, or only the
  // moving ones once the static subtrees are in place (updateAt on a scene with static vertices).
  uint32_t slotsUpdated = 0;
  double totalMs() const { return interpolateMs + refitMs + woopMs; }
};

// Device time of a rendered frame beyond the ray passes of RenderStats.
struct GpuRenderTimings {
  double generateMs = 0.0;  // ray generation, surfaces of the primary hits
  double shadeMs = 0.0;     // pixel colours
  double downloadMs = 0.0;  // image to the host (0 when no image was asked for)
  double totalMs = 0.0;     // first to last event of the frame, ray passes included
};

class GpuRuntime {
 public:
  struct Config {
    int device = 0;
    // true: Aila-Laine persistent warps fetching rays from a global counter (with dynamic fetch);
    // false: one thread per ray, the same while-while loop. On the H200 one thread per ray was
    // faster (docs/cuda-runtime.md), so it is the default.
    bool persistentTraversal = false;
    // updateAt and rebuildAt replay a CUDA graph captured at their first call (one per rebuild
    // configuration) instead of launching each kernel: the device then runs the frame's kernels
    // back to back instead of waiting for the host between launches of small kernels.
    bool useGraphs = true;
    // Layout of the traced tree: the refitted one, and the rebuilt ones (cwbvh: every rebuild is
    // converted into the compressed 8-wide layout on the device, RebuildTimings::wideMs).
    Layout layout = Layout::Bvh2;
    // renderFrameGpu makes each ray in the kernel that traces it (three fused passes over the
    // pixels that found a surface, no ray buffers; both layouts); false runs separate generation
    // and trace kernels over every padded pixel and sample (the reference the fused passes are
    // tested against).
    bool fusePasses = true;
    // Layout cwbvh: the objective of the 8-wide collapse of an uploaded tree over all its frames
    // (tsah::buildCwbvh(tree, objective): k, cT, cI and the largest leaf, as the CPU wide layouts'
    // tsah::wideCollapseConfig; leaves of at most 8) for a tree that brings none: the FlatBvh
    // constructors' tree and every tree of a set without build infos. A set with one BvhBuildInfo
    // per tree (as a .tbvh file gives) collapses each tree with its own objective.
    Objective wideObjective{};
    // Binary layout: updateAt refits the subtrees whose triangles never move only once
    // (docs/cuda-runtime.md#static-subtrees); false refits everything every time (the reference).
    bool skipStaticSubtrees = true;
  };

  // tree: the topology to refit (frame 0's block; its boxes are recomputed by updateAt). Throws
  // tsah::DataError when the tree does not match the animation, is invalid, or is deeper than the
  // traversal stack allows, and CudaError (a tsah::Failure) when the device fails.
  GpuRuntime(const FlatBvh& tree, const anim::Animation& animation, Config config);
  GpuRuntime(const FlatBvh& tree, const anim::Animation& animation);
  // A tree set: every tree is checked as above and uploaded once; updateAt(t) refits and traces the
  // tree of t's part (tsah::treeIndexAt: boundaries and overlaps as the CPU runtime), each tree
  // with its own captured graph. set.builds: empty, or one per tree (their objectives: see
  // Config::wideObjective).
  GpuRuntime(const TreeSet& set, const anim::Animation& animation, Config config);
  ~GpuRuntime();
  GpuRuntime(const GpuRuntime&) = delete;
  GpuRuntime& operator=(const GpuRuntime&) = delete;

  // The uploaded tree of t's part refitted to the animation at time t (clamped to its range), Woop
  // triangles recomputed; tracing uses it afterwards.
  UpdateTimings updateAt(double time);
  // Makes the tree of t's part current for update(positions) (updateAt does it itself); returns it.
  uint32_t selectTreeAt(double time);
  uint32_t treeCount() const;
  uint32_t currentTree() const;
  // The same for positions given by the host (vertexCount * 3 floats), as CpuRuntime::update: the
  // current tree (selectTreeAt) is refitted.
  UpdateTimings update(std::span<const float> positions);
  // A new tree for the animation at time t (or for the given positions); tracing uses it until the
  // next update. The uploaded tree is kept.
  RebuildTimings rebuildAt(double time, const RebuildOptions& options = {});
  RebuildTimings rebuild(std::span<const float> positions, const RebuildOptions& options = {});

  // Motion blur (docs/cuda-runtime.md): the current tree (selectTreeAt) refitted at every key of a
  // shutter from host positions, one box array per key. keyPositions[k]: vertexCount * 3 floats at
  // key k; keyTimes[k]: its shutter fraction (first 0, last 1, increasing). One key is update().
  // Tracing without times afterwards sees the last key. The timings add up the keys' updates; the
  // refit's includes copying each key's nodes and positions. Throws tsah::ConfigError for bad key times
  // or, with two keys or more, for layout cwbvh; tsah::DataError for a wrong coordinate count.
  UpdateTimings updateShutter(std::span<const float> keyTimes, std::span<const std::span<const float>> keyPositions);
  // The same from the uploaded keyframes for the shutter [open, close] (animation times): the keys are
  // open, every keyframe strictly inside and close; each key is interpolated and refitted on the
  // device in one batch, once per key (the instant state, what tracing without times sees, is the
  // last key's, taken from the batch), captured in a graph replayed while the key count and the tree
  // stay. A tree set traces each ray by the tree of its time, as the CPU runtime (docs/motion-blur.md):
  // the shutter is cut where the set hands over (tsah::shutterStretches), each part is its tree's
  // refit at the part's keys, and the last part's tree becomes the current one. open == close is
  // updateAt(open). Throws tsah::ConfigError for open > close.
  UpdateTimings updateShutterAt(double open, double close);
  // true after updateShutter(At) with two keys or more, until the next update, updateAt or rebuild.
  bool blurred() const;
  // Keys of the last updateShutter while blurred (all parts', a switch counted in each), else 0.
  uint32_t shutterKeyCount() const;
  // Host copies of key k of a blurred frame's last part (throws tsah::ConfigError when not blurred
  // or k is out of range): the refitted tree as downloadTree gives it, and the positions.
  FlatBvh downloadKeyTree(uint32_t key) const;
  std::vector<float> downloadKeyPositions(uint32_t key) const;
  // Host copy of the layout a blurred frame's last part is traced from (docs/motion-blur.md#memory), derived
  // from the key arrays: nodes[n * (keys - 1) + s] is node n's record of segment s
  // (motion::encodeNodeSegment of key s's and key s + 1's nodes, child boxes pre-padded over all
  // keys by motion::prepadBox, alike when they are the same at every key); triangles holds 12 floats
  // per slot and key, at (s * keys + k) * 12: the key-k positions of slot s's three vertices (v0 xyz,
  // v1 xyz, v2 xyz), 1 when they are the same at every key (else 0), and two zeros. Throws
  // tsah::ConfigError when not blurred.
  struct BlurredLayoutCopy {
    uint32_t keys = 0;
    std::vector<motion::BlurredNodeSegment> nodes;
    std::vector<float> triangles;
  };
  BlurredLayoutCopy downloadBlurredLayout() const;
  // Device bytes of the geometry a frame's tracing reads, the triangle indices and slot order
  // (which both read) left out. instant: the current tree's nodes and root, the positions and the
  // Woop triangles; blurred (0 unless blurred): per key of every part one node set, root box,
  // position set and shutter fraction, and the blurred layout (per segment a 96-byte record per
  // node, per key a 48-byte triangle per slot).
  struct FrameBytes {
    std::size_t instant = 0, blurred = 0;
  };
  FrameBytes frameBytes() const;

  bool tracingRebuiltTree() const;
  uint32_t triangleCount() const;
  uint32_t vertexCount() const;
  const DeviceInfo& device() const;
  const Config& config() const;

  // Host copies of the current state (each synchronizes).
  std::vector<float> downloadPositions() const;
  std::vector<WoopTriangle> downloadWoop() const;  // per slot of the traced tree
  // The traced tree with this frame's boxes (frameCount 1): the uploaded topology in its canonical
  // order after an update, the canonical form of the rebuilt tree after a rebuild.
  FlatBvh downloadTree() const;
  // The last rebuilt tree as a tsah::Bvh (one frame of boxes), exactly as built on the device.
  Bvh downloadRebuiltTree() const;
  Aabb bounds() const;  // of the traced tree
  // Layout cwbvh: the compressed nodes of the last update or rebuild (throws tsah::ConfigError
  // for layout bvh2).
  std::vector<CwbvhNode> downloadCwbvhNodes() const;
  // Layout cwbvh after a rebuild: the compressed tree the rebuild was converted to (nodes and
  // triIndex; rootRef 0), as tsah::convertToCwbvh makes it from downloadRebuiltArrays().
  CwbvhTree downloadRebuiltCwbvh() const;
  // The last rebuilt binary tree's arrays exactly as the device holds them: every node of the
  // rebuilder's array (interiorCount of them, in its order, unreferenced ones included: not the
  // canonical form), the root reference, count and box, and triIndex (binary slot -> triangle).
  FlatBvh downloadRebuiltArrays() const;

  // Traces host rays against the traced tree (closest hit / any hit). stats: ray count and the
  // traversal kernel's device time.
  std::vector<Hit> closestHits(std::span<const Ray> rays, RayPassStats* stats = nullptr);
  std::vector<uint8_t> anyHits(std::span<const Ray> rays, RayPassStats* stats = nullptr);

  // The same for rays at shutter fractions times[i] in [0, 1] (one per ray; outside values are
  // clamped) against a blurred frame (updateShutter, binary layout): boxes and triangles at each
  // ray's time. A frame that is not blurred ignores the times. Throws tsah::ConfigError when the
  // counts differ.
  std::vector<Hit> closestHits(std::span<const Ray> rays, std::span<const float> times, RayPassStats* stats = nullptr);
  std::vector<uint8_t> anyHits(std::span<const Ray> rays, std::span<const float> times, RayPassStats* stats = nullptr);

  // Device arrays (docs/cuda-runtime.md#device-arrays): the caller's CUDA memory used in place,
  // with no copy through the host. Work runs on the runtime's own stream, ordered after the work the
  // caller put on `stream` before the call and before the work it puts there after it (events, no
  // host wait), so a caller that syncs its stream sees the results. A CUDA stream (cudaStream_t) as
  // an opaque handle, so that this header needs no cuda_runtime.h; nullptr is the legacy default
  // stream, (void*)2 the per-thread default stream.
  using StreamHandle = void*;
  // When updateFromDevice reports a bad coordinate (docs/cuda-runtime.md#device-arrays).
  enum class DeviceCheck {
    Wait,      // the call waits for the update (and its check's answer) and throws at once
    Deferred,  // no host wait: a refused frame is thrown by a later call (see updateFromDevice)
  };
  // Refits the current tree (selectTreeAt) to the vertex positions at devicePositions (vertexCount
  // * 3 floats x y z in device memory of the runtime's device), as update(positions): one kernel
  // checks every coordinate (finite, |x| <= tsah::kMaxCoordinate), the next copies the positions
  // into the runtime only when all are good, then the refit and Woop pass run (a captured graph).
  // A refused frame changes nothing the trace reads (nodes, Woop triangles, positions). Throws
  // tsah::DataError for a wrong vertex count or a bad coordinate ("positions: vertex N has a NaN or
  // infinite coordinate", the wording of the host check), tsah::ConfigError for a pointer that is
  // not device memory of the runtime's device.
  // check Wait: the call waits for the check's answer (with the update's end). check Deferred: no
  // host wait while the traced frame is a refit of the current tree (an update, updateAt or an
  // earlier updateFromDevice of it; otherwise the call waits as Wait does); a refused frame is
  // thrown by the next updateFromDevice, update, updateAt, rebuild, rebuildAt or
  // checkDeviceUpdate, which then does nothing else; work queued in between (traces, renders)
  // sees the frame before the refused one.
  void updateFromDevice(const float* devicePositions, std::size_t vertexCount, StreamHandle stream = nullptr,
                        DeviceCheck check = DeviceCheck::Wait);
  // Waits for the check of the last Deferred updateFromDevice (if not reported yet) and throws its
  // tsah::DataError when it refused the frame; each refusal is thrown once.
  void checkDeviceUpdate();
  // Rays in the caller's device memory as separate arrays (Python's (n, 3) float32 arrays): ray i
  // starts at origins[3i..3i+2] with direction directions[3i..3i+2]; tmin/tmax per ray, or, when
  // null, tminValue/tmaxValue for every ray. The traversal reads these arrays directly (no packed
  // Ray buffer). Device rays are not checked as tsah::checkRays checks host rays (that would need a
  // wait); the scalar limits are (tsah::ConfigError).
  struct DeviceRays {
    const float* origins = nullptr;
    const float* directions = nullptr;
    const float* tmin = nullptr;
    const float* tmax = nullptr;
    float tminValue = 0.0f;
    float tmaxValue = std::numeric_limits<float>::infinity();
    std::size_t count = 0;
  };
  // Closest hits of device rays, one value per ray in each non-null array (device memory): t, u, v
  // (float) and triangle (uint32, the animation's triangle id). A miss writes t = +inf, u = v = 0,
  // triangle = tsah::kNoHit (0xffffffff), as the Python module reports misses.
  struct DeviceHits {
    float* t = nullptr;
    float* u = nullptr;
    float* v = nullptr;
    uint32_t* triangle = nullptr;
  };
  // Trace device rays against the traced tree (as closestHits / anyHits(rays): a blurred frame's
  // last key), one thread per ray; nothing waits for the device. occluded: one byte per ray, 1 when
  // something is hit within (tmin, tmax). Throws tsah::ConfigError when nothing is traceable yet,
  // for a null ray array, more than 2^32 - 1 rays, or a pointer that is not device memory of the
  // runtime's device.
  void closestHitsOnDevice(const DeviceRays& rays, const DeviceHits& hits, StreamHandle stream = nullptr);
  void anyHitsOnDevice(const DeviceRays& rays, uint8_t* occluded, StreamHandle stream = nullptr);

  struct Impl;

 private:
  friend RenderStats renderFrameGpu(GpuRuntime&, const Camera&, const SceneLighting&, const RenderSettings&, Image*,
                                    GpuRenderTimings*);
  friend struct QueryAccess;  // gpu_queries.hpp's entry points
  std::unique_ptr<Impl> impl_;
};

// tsah::renderFrame on the GPU for the runtime's current frame: the same passes, random numbers and
// shading; a blurred frame (blurred()) traces every ray of a pixel at the pixel's shutter time
// (tsah::pixelShutterTime), as the CPU renderer does. image == nullptr skips the download (benchmarks). Throws tsah::ConfigError for an
// empty image size or an invalid camera, as the CPU renderer does.
RenderStats renderFrameGpu(GpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                           const RenderSettings& settings, Image* image, GpuRenderTimings* timings = nullptr);
inline RenderStats renderFrameGpu(GpuRuntime& runtime, const Camera& camera, const SceneLighting& lighting,
                                  const RenderSettings& settings, Image& image, GpuRenderTimings* timings = nullptr) {
  return renderFrameGpu(runtime, camera, lighting, settings, &image, timings);
}

}  // namespace tsah::cuda
