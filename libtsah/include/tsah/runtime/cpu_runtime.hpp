#pragma once
// The CPU runtime: holds one tree in GPU-ready form plus this frame's vertices and Woop triangles.
// Per frame: update() refits the boxes bottom-up and recomputes the Woop triangles in one parallel
// pass over disjoint subtrees (then the few nodes above them); rebuild() instead builds a new tree
// from this frame's triangle boxes (the per-frame rebuild baseline).
//
// Layouts: the binary tree as given (bvh2, traversal.hpp), or a 4- or 8-wide tree derived from it
// once at construction by the multi-frame cost-optimal collapse (wide_bvh.hpp, over the frames the
// given tree holds) and traced with the SIMD kernels of one instruction set (wide_traversal.hpp).
// closestHit()/anyHit() trace the current frame in whichever layout was chosen.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tsah/core/bvh.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/traversal.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/layout/wide_bvh.hpp"
#include "tsah/layout/wide_traversal.hpp"
#include "tsah/layout/wide_tree.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah {

// The CPU runtime traces Layout::Bvh2, Bvh4 and Bvh8 (core/kinds.hpp).
// The layout with the most children the processor's best kernels support (bvh8 with AVX2), or,
// given an instruction set the processor runs, that set's kernels support (bvh4 with SSE).
Layout fastestLayout(std::optional<SimdIsa> isa = std::nullopt);
// False when no kernels of this build that the processor runs have this width.
bool layoutSupported(Layout layout);

// What a runtime traces: the layout, the kernels and the tree's size and multi-frame costs.
struct LayoutInfo {
  Layout layout = Layout::Bvh2;
  SimdIsa isa = SimdIsa::Sse;    // wide layouts: the kernels' instruction set
  TriangleForm triangles = TriangleForm::Woop;  // how the tree holds the frame's triangles (Config::triangles)
  uint32_t interiorNodes = 0, leaves = 0, depth = 0;
  // T-SAH cost C~^k (Eq. 3, the collapse's cT, cI, k) over the frames of the tree given to the
  // constructor: of that binary tree, and of the traced layout (equal for bvh2). 0 after rebuild().
  double binaryCost = 0.0, layoutCost = 0.0;
};

class CpuRuntime {
 public:
  struct Config {
    Config(uint32_t workerThreads = 0) : threads(workerThreads) {}  // NOLINT: {threads} converts
    uint32_t threads = 0;  // worker threads; 0 (or more than the hardware has): one per hardware thread
    Layout layout = Layout::Bvh2;
    std::optional<SimdIsa> isa;  // wide layouts: the kernels to use (default: the best supported)
    WideCollapser::Config collapse;  // wide layouts: cost constants, k, leaf size (width, leafPacket: the layout's)
    // Wide layouts: how the tree holds each frame's triangles (TriangleForm, wide_layout.hpp). Woop
    // (the default, what `tsah export` writes); Vertices computes no Woop rows in its refits, for
    // trees refitted every frame. The binary layout has only the Woop form.
    TriangleForm triangles = TriangleForm::Woop;
    // The vertices that may move between updates (ascending ids below the vertex count; an
    // animation's anim::Animation::movingVertices()). When set, an update() that follows another
    // (not a blurred frame, a rebuild or a switch to another tree of a set) reads only these
    // vertices' coordinates and refits only the subtrees whose triangles use them: the others keep
    // their boxes and Woop triangles, and the other vertices the positions of the last full update
    // (the tree equals a full refit's bit for bit when they did not change). Likewise the keys of
    // a blurred frame (updateShutter) once positions were read in full. Unset: all may move.
    std::optional<std::vector<uint32_t>> movingVertices;
    // The runtime's parallel loops (its refits) run as nested loops in the task arena of the
    // thread that calls it, not in an arena of `threads` workers of its own; they are still split
    // for `threads` workers. For runtimes updated side by side inside the caller's own parallel
    // loop (TwoLevelRuntime's BLAS): the caller's threads then share out the parts of every tree,
    // where each tree on one thread would leave threads idle behind the last trees.
    bool nested = false;
  };

  // Builds a tree over one frame of triangle boxes (indexed by triangle id); used by rebuild().
  using TreeBuilder = std::function<Bvh(std::span<const Aabb> triangleBoxes)>;

  struct RebuildTimings {
    double boxesMs = 0.0;    // triangle boxes of the frame
    double buildMs = 0.0;    // the builder itself (plus leaf collapse if it does one)
    double flattenMs = 0.0;  // conversion to the GPU layout
    double refitMs = 0.0;    // the refit + Woop pass on the new tree
  };

  // tree: the topology (boxes are recomputed by update(); a wide layout is collapsed using every
  // frame block the tree holds). indices: 3 per triangle, the animation's topology, each <
  // vertexCount. Throws tsah::DataError when the tree does not match the triangle count, is
  // invalid or is deeper than the traversal stack allows, tsah::ConfigError when the layout /
  // instruction set is not supported.
  CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount, Config config);
  CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount);
  // A tree set: every tree is checked as above and kept (a wide layout collapses each tree once,
  // here: with the objective of its own build info when the set has one per tree, as read from a
  // file, else with config.collapse's); selectTreeAt picks the one to refit and trace (tree 0 until
  // then; layoutInfo() describes tree 0). Throws tsah::DataError for an empty set or build infos
  // for only some trees.
  CpuRuntime(const TreeSet& set, std::vector<uint32_t> indices, uint32_t vertexCount, Config config);
  ~CpuRuntime();
  CpuRuntime(const CpuRuntime&) = delete;
  CpuRuntime& operator=(const CpuRuntime&) = delete;

  // Takes this frame's vertex positions (vertexCount * 3 floats), refits every box and recomputes
  // the Woop triangles (with Config::movingVertices: only the moving parts, see there). Throws
  // tsah::DataError ("runtime: ...") for a wrong count or a coordinate that is NaN, infinite or
  // beyond tsah::kMaxCoordinate (the limit imported animations obey); then nothing changed.
  void update(std::span<const float> positions);
  // Whether the last update() refitted only the moving parts.
  bool lastUpdateMovingOnly() const { return lastUpdateMovingOnly_; }
  // Takes this frame's positions and replaces the tree by builder(triangle boxes), then refits as
  // update() does (which also computes the Woop triangles).
  RebuildTimings rebuild(std::span<const float> positions, const TreeBuilder& builder);
  // Makes the tree of the part holding `time` (tsah::treeIndexAt: boundaries and overlaps included)
  // the current one and returns its index; update() must follow before tracing. A runtime made from
  // one tree, or after a rebuild, keeps its tree and returns 0.
  uint32_t selectTreeAt(double time);
  uint32_t treeCount() const { return setTrees_.empty() ? 1u : static_cast<uint32_t>(setTrees_.size()); }
  uint32_t currentTree() const { return current_; }

  // Nearest hit / any hit in (ray.tmin, ray.tmax) in the current frame, in the runtime's layout
  // (blurred: at time 1, below).
  // `order` picks the wide layouts' any-hit child order (the answer is the same; bvh2 ignores it):
  // the default for long rays such as shadow rays, AnyHitOrder::TreeOrder for short ones (ambient
  // occlusion).
  Hit closestHit(const Ray& ray) const;
  bool anyHit(const Ray& ray, AnyHitOrder order = AnyHitOrder::FarthestFirst) const;

  // Motion blur (docs/motion-blur.md). Refits the current tree at every key of a shutter:
  // keyPositions[k] = vertexCount*3 floats at key k, keyTimes[k] the key's shutter fraction (first
  // 0, last 1, increasing). One key is update(keyPositions[0]). Throws tsah::ConfigError for bad key
  // times or a key count that differs from the position sets, tsah::DataError for a position set of
  // the wrong size or a bad coordinate (as update()), tsah::Failure when the key sets do not fit in
  // memory; an error leaves the runtime as it was. update(), rebuild() and
  // selectTreeAt() return to the instant state. A key whose positions equal, bit for bit, a key of
  // the previous updateShutter keeps that key's refit (frames whose shutters meet share the key
  // between them), so a frame costs one refit per new key; the key sets equal a fresh update's.
  // With Config::movingVertices, once positions were read in full (an update() or a key before), a
  // key reads only the moving vertices' coordinates (the others keep the positions read before), and
  // a key set that already holds a refit of this tree refits only the moving nodes.
  // While blurred, positions() and bounds() are the last key's, closestHit(ray) / anyHit(ray)
  // trace at time 1 (the last key), and the instant triangles (woop(), the wide trees' packet
  // rows) and binary tree (tree(), view()) are not kept up to date (a blurred frame reads none).
  void updateShutter(std::span<const float> keyTimes, std::span<const std::span<const float>> keyPositions);
  // A tree set's blurred frame whose shutter crosses switch times (tsah::switchTime): one part per
  // stretch of the shutter, each refitted with its own tree at its own keys, so that every ray is
  // traced by the tree of its time. Key times are fractions of the whole shutter: the first part's
  // first is 0, the last part's last 1, and each part starts at its predecessor's last key (the
  // switch; both parts refit the positions there). A ray at time t takes the last part starting at
  // or before t. keysRefitted(), the reuse of the previous frame's keys (per tree), the errors and
  // the unchanged runtime on an error are as above; the last part's tree becomes the current one.
  // Throws tsah::ConfigError for no parts, a part of fewer than two keys (when there are several),
  // parts that do not meet, a tree index past the set or a tree repeated.
  struct ShutterPart {
    uint32_t tree = 0;
    std::span<const float> keyTimes;
    std::span<const std::span<const float>> keyPositions;
  };
  void updateShutter(std::span<const ShutterPart> parts);
  // True after updateShutter with two keys or more (until update()).
  bool blurred() const { return !parts_.empty(); }
  // The parts of the blurred frame (1 unless a tree set's shutter crossed a switch; 0 when not
  // blurred) and each one's tree; all parts' keys (a switch counted in both parts); the time
  // ranges of a set's trees (empty for a single tree).
  uint32_t shutterPartCount() const { return static_cast<uint32_t>(parts_.size()); }
  uint32_t shutterPartTree(std::size_t part) const { return parts_.at(part).tree; }
  uint32_t shutterKeyCount() const;
  std::span<const TimeRange> treeRanges() const { return setRanges_; }
  // How many keys the last updateShutter refitted (the others were reused); 0 when not blurred.
  uint32_t keysRefitted() const { return keysRefitted_; }
  // How many of those refitted only the moving nodes (Config::movingVertices).
  uint32_t keysRefittedMovingOnly() const { return keysRefittedMovingOnly_; }
  // Key times of a part (shutter fractions; empty when not blurred or past the parts).
  std::span<const float> keyTimes(std::size_t part = 0) const {
    return part < parts_.size() ? std::span<const float>(parts_[part].keyTimes) : std::span<const float>();
  }
  // Nearest hit / any hit at the ray's time, a shutter fraction in [0, 1] (outside: the nearer end).
  // Not blurred: closestHit(ray) / anyHit(ray, order).
  Hit closestHit(const Ray& ray, float time) const;
  bool anyHit(const Ray& ray, float time, AnyHitOrder order = AnyHitOrder::FarthestFirst) const;
  // A part of the blurred frame (valid while blurred(), part < shutterPartCount()): key times,
  // positions, root boxes and triangles in every layout; the binary key nodes (keyNodes) in bvh2
  // only, null in the wide layouts, which keep their own node set per key and trace through
  // closestHit / anyHit(ray, time). motionViewAt: the part that traces a ray at time t.
  const MotionBvhView& motionView(std::size_t part = 0) const;
  const MotionBvhView& motionViewAt(float time) const { return motionView(partAt(time)); }
  // The wide layouts' blurred sets of key k < keyTimes(part).size(): its nodes (in the part's
  // tree's wide4()/wide8()->nodes() order) and its triangles, one KeyVertexPacket per Woop packet
  // (empty when not blurred, k or part is past the keys, or in another layout).
  std::span<const WideSoaNode<4>> keyWideNodes4(std::size_t k, std::size_t part = 0) const {
    return wideKeyPart(&BlurredPart::wide4, part, k, &WideKey<4>::nodes);
  }
  std::span<const WideSoaNode<8>> keyWideNodes8(std::size_t k, std::size_t part = 0) const {
    return wideKeyPart(&BlurredPart::wide8, part, k, &WideKey<8>::nodes);
  }
  std::span<const KeyVertexPacket<4>> keyVertexPackets4(std::size_t k, std::size_t part = 0) const {
    return wideKeyPart(&BlurredPart::wide4, part, k, &WideKey<4>::vertices);
  }
  std::span<const KeyVertexPacket<8>> keyVertexPackets8(std::size_t k, std::size_t part = 0) const {
    return wideKeyPart(&BlurredPart::wide8, part, k, &WideKey<8>::vertices);
  }

  const LayoutInfo& layoutInfo() const { return info_; }
  // The binary tree and its view: bvh2 only (the wide layouts do not refit the binary tree; both
  // throw tsah::ConfigError for them).
  BvhView view() const;
  const FlatBvh& tree() const;
  // The wide tree of a bvh4 / bvh8 runtime (null otherwise).
  const WideTree<4>* wide4() const { return wide4_.get(); }
  const WideTree<8>* wide8() const { return wide8_.get(); }
  std::span<const WoopTriangle> woop() const { return woop_; }
  std::span<const float> positions() const { return positions_; }
  std::span<const uint32_t> indices() const { return indices_; }
  uint32_t triangleCount() const { return static_cast<uint32_t>(indices_.size() / 3); }
  uint32_t vertexCount() const { return vertexCount_; }
  Aabb bounds() const;  // of the current frame
  uint32_t threadCount() const;

  // Runs body(begin, end) over chunks of [0, n) on the runtime's threads (chunks of about `grain`).
  void parallelFor(std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body) const;

 private:
  void setTree(FlatBvh tree);
  FlatBvh topologyOf(const FlatBvh& tree) const;  // frame 0's block, validated against this runtime
  void setWideTree(const Bvh& binary, bool reportCosts);
  BvhView binaryView() const;
  void checkPositions(std::span<const float> positions) const;  // count and coordinates (update's errors)
  void checkMovingPositions(std::span<const float> positions) const;  // count and the moving vertices' coordinates
  void setPositions(std::span<const float> positions);
  // movingOnly: the nodes of the moving plan only (Config::movingVertices, after a full refit).
  void refitAndWoop(bool movingOnly = false);
  void clearShutter();
  void switchTree(uint32_t index);  // the set's tree `index` becomes the current one (the shutter stays)
  void refitNode(uint32_t node);
  Aabb refitLeaf(uint32_t firstSlot, uint32_t count);

  struct Threads;
  std::unique_ptr<Threads> threads_;
  template <class F>
  void inArena(const F& f) const;  // runs f where the runtime's loops run (Config::nested)
  FlatBvh tree_;
  std::vector<uint32_t> indices_;
  uint32_t vertexCount_ = 0;
  std::vector<float> positions_;
  std::vector<WoopTriangle> woop_;
  // Parallel refit plan: disjoint subtrees [root, end) refitted in parallel, then the nodes above
  // them (descending index, children before parents) on one thread.
  std::vector<std::pair<uint32_t, uint32_t>> subtreeTasks_;
  std::vector<uint32_t> topNodes_;
  // Config::movingVertices (checked), the binary tree's moving nodes (the wide trees keep their
  // own), and whether the last full refit is the current tree's and instant (then an update may
  // refit the moving parts only).
  std::optional<std::vector<uint32_t>> movingVertices_;
  std::shared_ptr<const detail::MovingRefitPlan> movingPlan_;
  bool staticRefitted_ = false;
  bool lastUpdateMovingOnly_ = false;
  // Whether positions_ holds every vertex's coordinates as read (an update, a rebuild or a
  // blurred frame's key read them in full): the static vertices' then stay valid.
  bool staticPositionsRead_ = false;
  // Wide layouts.
  LayoutInfo info_;
  const WideKernels* kernels_ = nullptr;
  WideCollapser::Config collapse_;
  std::shared_ptr<WideTree<4>> wide4_;
  std::shared_ptr<WideTree<8>> wide8_;
  WideView<4> view4_;
  WideView<8> view8_;
  // Tree set: every tree's topology and time range (and, for a wide layout, its wide tree, collapsed
  // once up front); current_ indexes them (0 for a single tree).
  std::vector<FlatBvh> setTrees_;
  std::vector<TimeRange> setRanges_;
  uint32_t current_ = 0;
  std::vector<std::shared_ptr<WideTree<4>>> setWide4_;
  std::vector<std::shared_ptr<WideTree<8>>> setWide8_;
  // Motion blur: the wide layouts keep per key their own node set and vertex packets, so that a key
  // reused by the next shutter moves instead of being copied, and a new key refits into a dropped
  // key's buffers.
  template <uint32_t N>
  struct WideKey {
    std::vector<WideSoaNode<N>> nodes;
    std::vector<KeyVertexPacket<N>> vertices;
    bool refitted = false;  // the sets hold a refit of the part's tree (a moving-only refit may follow)
  };
  // Per segment s of a part (keys s and s + 1), the wide kernels' frame but for the ray's f: made
  // once per updateShutter, so that a ray only looks up its part and segment.
  template <uint32_t N>
  struct WideSegment {
    WideView<N> view;            // key s: nodes, positions (rootBox: see traceSegment)
    WideMotionFrame<N> motion;   // key s + 1's nodes, both keys' vertex packets
  };
  // One part of a blurred frame: its tree, its key times and per key the refitted nodes (bvh2) or
  // wide sets, root box and positions; `view` points into them (no parts when not blurred).
  struct BlurredPart {
    uint32_t tree = 0;
    std::vector<float> keyTimes;
    std::vector<GpuBvhNode> keyNodes;
    std::vector<Aabb> keyRootBoxes;
    std::vector<float> keyPositions;
    std::vector<WideKey<4>> wide4;
    std::vector<WideKey<8>> wide8;
    std::vector<WideSegment<4>> segments4;
    std::vector<WideSegment<8>> segments8;
    MotionBvhView view;
  };
  std::vector<BlurredPart> parts_;
  uint32_t keysRefitted_ = 0;
  uint32_t keysRefittedMovingOnly_ = 0;
  std::vector<float> spareKeyPositions_;  // a dropped part's, kept as the next one's buffer
  std::size_t partAt(float time) const;
  template <uint32_t N, class T>
  std::span<const T> wideKeyPart(std::vector<WideKey<N>> BlurredPart::*keys, std::size_t part, std::size_t k,
                                 std::vector<T> WideKey<N>::*field) const {
    if (part >= parts_.size()) return {};
    const std::vector<WideKey<N>>& sets = parts_[part].*keys;
    return k < sets.size() ? std::span<const T>(sets[k].*field) : std::span<const T>();
  }
  // The part of `tree` at `keyTimes`, made from `old` (the previous frame's part of this tree, or an
  // empty one): keys equal to old ones (reused[k] < old's key count) are taken from it, the others
  // refitted (readMovingOnly: positions_ with the key's moving vertices).
  BlurredPart makePart(uint32_t tree, std::span<const float> keyTimes, std::span<const std::span<const float>> keyPositions,
                       const std::vector<std::size_t>& reused, bool readMovingOnly, BlurredPart& old);
  void refitShutterKey(std::span<const float> positions, bool readMovingOnly, BlurredPart& out, std::size_t key);
  template <uint32_t N>
  void setSegments(const WideView<N>& view, BlurredPart& part, std::vector<WideKey<N>> BlurredPart::*keys,
                   std::vector<WideSegment<N>> BlurredPart::*segments);
  // trace(view, motion) on the segment of the ray's time in the part.
  template <uint32_t N, class Trace>
  auto traceSegment(const BlurredPart& part, const std::vector<WideSegment<N>>& segments, float time,
                    const Trace& trace) const;
};

}  // namespace tsah
