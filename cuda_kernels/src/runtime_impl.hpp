#pragma once
// GpuRuntime's state (shared by gpu_runtime.cpp and render.cu).
#include <span>
#include <cuda_runtime_api.h>

#include <functional>
#include <memory>
#include <type_traits>
#include <vector>

#include "blurred_trace.hpp"
#include "device_types.hpp"
#include "event_timer.hpp"
#include "kernels.hpp"
#include "rebuild.hpp"
#include "render_passes.cuh"
#include "tsah/layout/cwbvh_build.hpp"
#include "tsah/base/error.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace tsah::cuda {

struct DeviceArrayState;  // device_arrays_runtime.cpp

struct GpuRuntime::Impl {
  Impl(const TreeSet& set, const anim::Animation& animation, Config config);
  ~Impl();
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  detail::TraceScene scene() const;
  detail::TraceLaunch traceLaunch() const { return {config.persistentTraversal, 128, 0}; }
  // Throws unless there is a traceable frame (an update or a rebuild with Woop triangles).
  void requireTraceable() const;
  // The refit on the stream and the Woop pass beside it (events 2 and 3, 12 and 13); finishUpdate
  // waits and reads the timings (events 0..3). movingOnly: only the current tree's moving parts
  // (partialUpdatePossible must hold).
  void enqueueRefitAndWoop(bool movingOnly = false);
  // True when updateAt may refit only the moving parts of the current tree: it has static parts, a
  // full update from the animation put their boxes in place, the Woop buffer holds that tree's
  // triangles since then, and the static vertices are at their rest positions.
  bool partialUpdatePossible() const;
  UpdateTimings finishUpdate(uint32_t slotsUpdated);
  // What finishUpdate records of a queued update without waiting for it: the frame is traceable,
  // the refitted tree is traced, a blurred frame ends.
  void markUpdated();
  // True when the traced frame is a refit of the current tree (an update, updateAt or
  // updateFromDevice of it since the last selectTreeAt, rebuild or blurred frame): refitting it
  // again from the same positions gives the same frame bit for bit.
  bool tracingRefitOfCurrentTree() const {
    return woopValid && !tracingRebuilt && shutterKeys == 0 && frameTree == int(current);
  }
  // Throws the tsah::DataError of a Deferred updateFromDevice that refused its frame, once
  // (device_arrays_runtime.cpp); waits for its check when the answer is not in yet.
  void throwRefusedDeviceUpdate();
  // The triangles of every vertex in increasing order (once, at the first render).
  void buildVertexTriangles();
  // Puts the interpolation of time t on the stream (events 0 and 1 around it): setFrame chooses the
  // keyframes (frame), enqueueInterpolation launches with them; a captured graph gets them from
  // launch(), so the same work is captured once.
  void setFrame(double time);
  void enqueueInterpolation();
  // The current tree refitted to the animation at `time` (its captured graph), Woop included.
  UpdateTimings refitAt(double time);
  // Puts the static vertices' rest positions back into `positions` when an update from host
  // positions overwrote them (the interpolation writes only the moving vertices).
  void restoreStaticPositions();
  // A captured graph, kept with its interpolation node (whose frame launch() sets).
  struct CapturedGraph {
    cudaGraph_t graph = nullptr;
    cudaGraphExec_t exec = nullptr;
    detail::InterpolationNode interpolation;  // node null: the graph interpolates nothing
  };
  // Captures what `enqueue` puts on the stream into an executable graph.
  template <typename Enqueue>
  CapturedGraph capture(Enqueue&& enqueue);
  // Launches a captured graph for the current frame.
  void launch(const CapturedGraph& g);
  static void destroy(CapturedGraph& g) noexcept;

  Config config;
  DeviceInfo device;
  cudaStream_t stream = nullptr;
  cudaStream_t sideStream = nullptr;  // the renderer's shadow pass, beside the AO pass on `stream`
  detail::EventTimer events;  // created once the device is chosen

  uint32_t triangles = 0, vertices = 0;
  std::vector<double> times;             // keyframe times
  std::vector<uint32_t> hostIndices;     // for buildVertexTriangles
  uint32_t movingVertices = 0;           // vertices that move; the others keep their rest position
  DeviceBuffer<float> keyframes;         // every keyframe of the moving vertices, movingVertices * 3 floats each
  DeviceBuffer<uint32_t> movingIds;      // ascending ids of the moving vertices; empty when every vertex moves
  std::vector<float> hostRest;           // rest positions of every vertex; empty when every vertex moves
  bool restInPlace = true;               // `positions` holds the rest positions of the static vertices
  DeviceBuffer<uint32_t> indices;        // 3 per triangle
  DeviceBuffer<float> positions;         // the current frame
  detail::FrameParams frame;             // the keyframes of the current frame (setFrame)
  struct RebuildGraph {
    RebuildOptions options;
    CapturedGraph graph;
  };
  std::vector<RebuildGraph> rebuildGraphs;

  // The compressed 8-wide layout of one tree (Config::layout == cwbvh), refitted and re-quantized
  // by every update; woop then holds its slots' triangles.
  struct Cwbvh {
    CwbvhTree host;                      // topology (and frame-0 quantization) as built on the host
    DeviceBuffer<CwbvhNode> nodes;
    DeviceBuffer<Aabb> nodeBoxes;         // per node: the exact union of its children, this frame
    DeviceBuffer<uint32_t> triIndex;
    DeviceBuffer<uint32_t> slotVertices;  // 3 vertex ids per slot, for the refit and the Woop pass
    detail::CwbvhRefitPlan refit;
    DeviceBuffer<detail::RootInfo> root;
  };
  // The uploaded trees (canonical order, one block of nodes each): one, or a tree set's K, all
  // uploaded once; updateAt refits the tree of the frame's part (tsah::treeIndexAt over ranges).
  struct DeviceTree {
    FlatBvh topology;                    // host copy of its structure
    DeviceBuffer<GpuBvhNode> nodes;
    DeviceBuffer<uint32_t> nodeParent, counters, triIndex;
    DeviceBuffer<uint32_t> slotVertices;  // 3 vertex ids per slot, for the refit and the Woop pass
    DeviceBuffer<detail::LeafRecord> leaves;
    DeviceBuffer<detail::RootInfo> root;
    CapturedGraph updateGraph;              // updateAt's graph for this tree (captured at first use)
    // Static subtrees (tsah/layout/moving_parts.hpp), binary layout: when some triangles never move,
    // updateAt refits from the moving leaves only, every node's arrival counter starting at its count
    // of static children, and recomputes the Woop triangles of the moving slots only.
    bool hasStaticParts = false;
    bool staticBoxesValid = false;          // a full update from the animation refitted the static subtrees
    DeviceBuffer<detail::LeafRecord> movingLeaves;
    DeviceBuffer<uint32_t> staticChildren;  // per interior node: children whose subtree never moves
    DeviceBuffer<uint32_t> movingSlots;     // slots whose triangle moves
    CapturedGraph partialUpdateGraph;       // updateAt's graph when only the moving parts are refitted
    std::unique_ptr<Cwbvh> cwbvh;           // the compressed layout, when Config::layout == cwbvh
  };
  // Validates one tree against the animation and uploads it (and its compressed layout).
  void createOnDevice(const TreeSet& set, const anim::Animation& animation, std::vector<FlatBvh> topologies);
  void uploadTree(const FlatBvh& tree, FlatBvh topologyOfTree, const Objective& wideObjective);
  void releaseDevice() noexcept;
  // The 8-wide collapse over all frames of `tree` for `objective`, its compressed layout and refit
  // data on the device.
  static std::unique_ptr<Cwbvh> uploadCwbvh(const FlatBvh& tree, std::span<const uint32_t> indices,
                                            const Objective& objective, cudaStream_t stream);
  DeviceTree& tree() { return trees[current]; }
  const DeviceTree& tree() const { return trees[current]; }
  std::vector<DeviceTree> trees;
  std::vector<TimeRange> ranges;         // one per tree
  uint32_t current = 0;                  // the tree that update/updateAt refit and tracing reads
  int frameTree = -1;                    // the tree the last update refitted (markUpdated)


  DeviceBuffer<WoopTriangle> woop;       // per slot of the traced tree
  bool woopValid = false;
  int woopTree = -1;                     // the tree whose every slot `woop` holds (full update), or -1
  std::vector<uint32_t> movingVertexIds; // the animation's moving vertices (empty: all move)
  bool tracingRebuilt = false;
  std::unique_ptr<detail::GpuRebuilder> rebuilder;
  // The caller's positions of every vertex (3 floats each) in place of the interpolated ones, timed
  // by events 0 and 1; throws tsah::DataError for a wrong count.
  void uploadPositions(std::span<const float> given);
  // The rebuilder after its last rebuild; throws tsah::ConfigError when nothing was rebuilt yet.
  const detail::GpuRebuilder& lastRebuild() const;

  // Motion blur: the keys of the last updateShutter (0 when the frame is not blurred), and per key
  // the traced tree's nodes, root and the positions (key-major).
  uint32_t shutterKeys = 0;
  std::vector<float> shutterKeyTimes;
  DeviceBuffer<GpuBvhNode> keyNodes;
  DeviceBuffer<Aabb> keyRootBoxes;
  DeviceBuffer<float> keyPositions;
  DeviceBuffer<float> keyFractions;      // the keys' shutter fractions
  DeviceBuffer<float> rayTimes;          // scratch: the shutter fraction of each host ray
  // Refits the current tree once per key (refitKey(k) leaves key k in `positions` and the tree) and
  // keeps every key; throws tsah::ConfigError for a layout other than bvh2.
  template <typename RefitKey>
  UpdateTimings refitKeys(std::span<const float> keyTimes, RefitKey&& refitKey);
  // updateShutterAt's keys from the animation: the current tree refitted at every key time in one
  // batch (one launch per step for all keys, detail::BatchStrides) straight into the key arrays,
  // each key once; the instant state (what tracing without times sees) is the last key's, copied
  // from the batch, with its Woop triangles; then the blurred layout.
  UpdateTimings refitAnimationKeys(std::span<const double> keyTimes, std::span<const float> fractions);
  DeviceBuffer<detail::FrameParams> keyFrames;  // per key: its keyframe blend
  DeviceBuffer<uint32_t> keyCounters;           // per key: the refit's arrival counters
  DeviceBuffer<detail::RootInfo> keyRoots;      // per key: the refit's root
  // The blurred layout (blurred_trace.hpp), built from the key arrays by every blurred update;
  // withInstantState: also the key root boxes and the last key's nodes, root box and positions as
  // the instant state, from the batch refit's roots (keyRoots).
  DeviceBuffer<motion::BlurredNodeSegment> blurNodes;  // (keys - 1) records per node
  DeviceBuffer<detail::KeyTriangle> blurTriangles;
  void enqueueBlurredLayout(uint32_t keys, bool withInstantState);
  // refitAnimationKeys' steps after the keys' uploads (events 0..3, as an update's).
  void enqueueShutterRefit(uint32_t keys);
  // Its graphs (config.useGraphs), one per key count and tree, each captured for its arguments (the
  // key count, the tree and the key arrays' addresses) and captured again when they change.
  struct ShutterGraphArgs {
    uint32_t keys = 0, tree = 0;
    const void* buffers[8] = {};
    bool operator==(const ShutterGraphArgs&) const = default;
  };
  struct ShutterGraph {
    ShutterGraphArgs args;
    CapturedGraph graph;
  };
  std::vector<ShutterGraph> shutterGraphs;
  // Key slots [0, keySlotsReady) hold tree keySlotsTree's child references and the rest positions
  // of the static vertices (refitAnimationKeys copies them into new slots only).
  uint32_t keySlotsReady = 0;
  int keySlotsTree = -1;
  // Throws tsah::ConfigError unless the layout is bvh2 (the only one traced blurred on the GPU).
  void requireBinaryLayout() const;
  // Throws tsah::ConfigError unless the frame is blurred and key < shutterKeys.
  void requireKey(uint32_t key) const;
  // A tree set's shutter that crosses switch times (updateShutterAt): one part per tree. The parts
  // before the last keep their key arrays and blurred layout here (the last part's are the members
  // above: what downloadKeyTree and the other key accessors read); laterParts holds the views of
  // parts 1, 2, ... on the device (detail::BlurredShutter::later).
  struct StoredPart {
    uint32_t tree = 0, keys = 0;
    float start = 0.0f;  // its first key time
    DeviceBuffer<GpuBvhNode> keyNodes;
    DeviceBuffer<Aabb> keyRootBoxes;
    DeviceBuffer<float> keyPositions, keyFractions;
    DeviceBuffer<motion::BlurredNodeSegment> blurNodes;
    DeviceBuffer<detail::KeyTriangle> blurTriangles;
  };
  std::vector<StoredPart> storedParts;
  uint32_t storedPartCount = 0;  // of the current blurred frame (0: one part)
  DeviceBuffer<detail::BlurredPart> laterParts;
  // Moves the last part's key arrays and layout into storedParts[p] (taking that slot's buffers).
  void storePart(uint32_t p);
  // The blurred frame's device arrays as the traversal reads them (the batch queries and the
  // renderer); only while blurred. motionView and blurredLayout: the last part's.
  MotionBvhView motionView() const;
  detail::BlurredLayout blurredLayout() const;
  detail::BlurredShutter blurredShutter() const;
  detail::BlurredPart blurredShutterPart(uint32_t p) const;  // p <= storedPartCount (the last)

  // Scratch of the ray queries (rays and hits also the renderer's separate passes), grown on demand.
  DeviceBuffer<uint32_t> words;          // the queries' ray counter
  DeviceBuffer<Ray> rays;
  DeviceBuffer<Hit> hits;
  DeviceBuffer<uint8_t> occluded;
  // The renderer's: the separate passes' shadow rays, what every frame's passes write, the normals.
  DeviceBuffer<Ray> shadowRays;
  detail::PassBufferSet passes;
  DeviceBuffer<uint32_t> vertexTriOffsets, vertexTris;  // triangles of each vertex (CSR), for normals
  DeviceBuffer<float> normals;           // smooth shading normals of the current frame

  // The device-array entry points' events and flag word (device_arrays_runtime.cpp), made at first use.
  std::shared_ptr<DeviceArrayState> deviceArrays;
};

// The graph's capture: everything `enqueue` puts on `stream` (and the streams it forks).
template <typename Enqueue>
inline GpuRuntime::Impl::CapturedGraph GpuRuntime::Impl::capture(Enqueue&& enqueue) {
  CUDA_CHECK(cudaStreamBeginCapture(stream, cudaStreamCaptureModeThreadLocal));
  try {
    enqueue();
  } catch (...) {
    cudaGraph_t broken = nullptr;
    cudaStreamEndCapture(stream, &broken);
    if (broken) cudaGraphDestroy(broken);
    throw;
  }
  CapturedGraph g;
  CUDA_CHECK(cudaStreamEndCapture(stream, &g.graph));
  // The graph stays alive with its executable: the interpolation node is updated through it.
  try {
    g.interpolation = detail::findInterpolationNode(g.graph);
    CUDA_CHECK(cudaGraphInstantiate(&g.exec, g.graph, 0));
  } catch (...) {
    destroy(g);
    throw;
  }
  return g;
}

// Traces host rays: uploads them, runs prepare(count) (more uploads), then launch(count, hits,
// occluded) between events 0 and 1 on the runtime's stream, and downloads the closest hits (Result
// Hit) or the occlusion flags (Result uint8_t). stats: the ray count and the launch's device time.
template <typename Result, typename Prepare, typename Launch>
std::vector<Result> traceHostRays(GpuRuntime::Impl& m, std::span<const Ray> rays, RayPassStats* stats,
                                  Prepare&& prepare, Launch&& launch) {
  constexpr bool anyHit = std::is_same_v<Result, uint8_t>;
  std::vector<Result> out(rays.size());
  if (rays.empty()) {
    if (stats) *stats = {};
    return out;
  }
  if (rays.size() > 0xffffffffu) throw tsah::ConfigError("GPU runtime: too many rays in one call");
  const auto count = static_cast<uint32_t>(rays.size());
  m.rays.reserve(count);
  m.rays.upload(rays, m.stream);
  if (anyHit)
    m.occluded.reserve(count);
  else
    m.hits.reserve(count);
  prepare(count);
  m.events.record(0, m.stream);
  launch(count, anyHit ? nullptr : m.hits.data(), anyHit ? m.occluded.data() : nullptr);
  m.events.record(1, m.stream);
  m.events.wait(1);
  if (stats) *stats = {count, m.events.ms(0, 1)};
  void* src = anyHit ? static_cast<void*>(m.occluded.data()) : static_cast<void*>(m.hits.data());
  CUDA_CHECK(cudaMemcpyAsync(out.data(), src, out.size() * sizeof(Result), cudaMemcpyDeviceToHost, m.stream));
  CUDA_CHECK(cudaStreamSynchronize(m.stream));
  return out;
}

}  // namespace tsah::cuda
