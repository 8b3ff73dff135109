#pragma once
// The CPU runtime: holds one tree in GPU-ready form plus this frame's vertices and Woop triangles.
// Per frame: update() refits the boxes bottom-up and recomputes the Woop triangles in one parallel
// pass over disjoint subtrees (then the few nodes above them); rebuild() instead builds a new tree
// from this frame's triangle boxes (the per-frame rebuild baseline). Traversal reads view().
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "tsah/bvh.hpp"
#include "tsah/flat_bvh.hpp"
#include "tsah/traversal.hpp"
#include "tsah/tree_set.hpp"
#include "tsah/woop.hpp"

namespace tsah {

class CpuRuntime {
 public:
  struct Config {
    uint32_t threads = 0;  // worker threads; 0 (or more than the hardware has): one per hardware thread
  };

  // Builds a tree over one frame of triangle boxes (indexed by triangle id); used by rebuild().
  using TreeBuilder = std::function<Bvh(std::span<const Aabb> triangleBoxes)>;

  struct RebuildTimings {
    double boxesMs = 0.0;    // triangle boxes of the frame
    double buildMs = 0.0;    // the builder itself (plus leaf collapse if it does one)
    double flattenMs = 0.0;  // conversion to the GPU layout
    double refitMs = 0.0;    // the refit + Woop pass on the new tree
  };

  // tree: the topology (frame 0's block is used; boxes are recomputed by update()). indices: 3 per
  // triangle, the animation's topology, each < vertexCount. Throws anim::Error when the tree does
  // not match the triangle count, is invalid, or is deeper than the traversal stack allows.
  CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount, Config config);
  CpuRuntime(const FlatBvh& tree, std::vector<uint32_t> indices, uint32_t vertexCount);
  // A tree set: every tree is checked as above and kept; selectTreeAt picks the one to refit and
  // trace (tree 0 until then). Throws anim::Error for an empty set.
  CpuRuntime(const TreeSet& set, std::vector<uint32_t> indices, uint32_t vertexCount, Config config);
  ~CpuRuntime();
  CpuRuntime(const CpuRuntime&) = delete;
  CpuRuntime& operator=(const CpuRuntime&) = delete;

  // Takes this frame's vertex positions (vertexCount * 3 floats), refits every box and recomputes
  // the Woop triangles.
  void update(std::span<const float> positions);
  // Takes this frame's positions and replaces the tree by builder(triangle boxes), then refits as
  // update() does (which also computes the Woop triangles).
  RebuildTimings rebuild(std::span<const float> positions, const TreeBuilder& builder);
  // Makes the tree of the part holding `time` (tsah::treeIndexAt: boundaries and overlaps included)
  // the current one and returns its index; update() must follow before tracing. A runtime made from
  // one tree, or after a rebuild, keeps its tree and returns 0.
  uint32_t selectTreeAt(double time);
  uint32_t treeCount() const { return setTrees_.empty() ? 1u : static_cast<uint32_t>(setTrees_.size()); }
  uint32_t currentTree() const { return current_; }

  BvhView view() const;
  const FlatBvh& tree() const { return tree_; }  // one frame of boxes: the current one
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
  void setPositions(std::span<const float> positions);
  void refitAndWoop();
  void refitNode(uint32_t node);
  Aabb refitLeaf(uint32_t firstSlot, uint32_t count);

  struct Threads;
  std::unique_ptr<Threads> threads_;
  FlatBvh tree_;
  std::vector<uint32_t> indices_;
  uint32_t vertexCount_ = 0;
  std::vector<float> positions_;
  std::vector<WoopTriangle> woop_;
  // Parallel refit plan: disjoint subtrees [root, end) refitted in parallel, then the nodes above
  // them (descending index, children before parents) on one thread.
  std::vector<std::pair<uint32_t, uint32_t>> subtreeTasks_;
  std::vector<uint32_t> topNodes_;
  // Tree set: every tree's topology and time range; current_ indexes them (0 for a single tree).
  std::vector<FlatBvh> setTrees_;
  std::vector<TimeRange> setRanges_;
  uint32_t current_ = 0;
};

}  // namespace tsah
