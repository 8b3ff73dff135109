#pragma once
// A wide tree in the CPU SIMD layout (wide_layout.hpp) with its per-frame refit: the nodes and
// Woop packets (or vertex packets: TriangleForm) of one frame, built from a WideBvh topology
// (wide_bvh.hpp). refit() recomputes every child box and packet from this frame's vertices in one
// parallel pass over disjoint subtrees (then the few nodes above them), as CpuRuntime does for the
// binary tree.
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "tsah/base/huge_pages.hpp"
#include "tsah/layout/wide_bvh.hpp"
#include "tsah/layout/wide_layout.hpp"
#include "tsah/layout/wide_traversal.hpp"

namespace tsah {

namespace detail {
struct MovingRefitPlan;
}

template <uint32_t N>
class WideTree {
 public:
  // Runs body(begin, end) over chunks of [0, n), possibly in parallel.
  using ParallelFor =
      std::function<void(std::size_t n, const std::function<void(std::size_t begin, std::size_t end)>& body)>;

  // topology.width must be at most N (a narrower topology leaves slots unused). indices: the
  // triangles (3 vertex indices per triangle id), the same for every frame; the tree keeps its own
  // copy in slot order. Boxes and triangles are zero until the first refit(). threads: how many
  // workers refit() will run on (it plans about 8 subtrees per thread). isa: whose SIMD code
  // computes the Woop rows (the results are the same for every one). Throws tsah::ConfigError when
  // the isa is not supported, tsah::DataError when the topology is invalid, too wide or too deep, or a
  // triangle id is past the index array. form: how refit() stores the triangles (TriangleForm).
  WideTree(const WideBvh& topology, std::span<const uint32_t> indices, uint32_t threads, SimdIsa isa = bestIsa(),
           TriangleForm form = TriangleForm::Woop);

  // This frame's vertices (xyz per vertex; every vertex index of the triangles must be in range).
  void refit(const float* positions, const ParallelFor& parallelFor);
  // The blurred refit at one key (docs/motion-blur.md) into the key's own sets: in keyNodes (a copy
  // of nodes(): its refs and counts) every box as refit() computes it, in keyVertices[p] (one per
  // packet) the vertices of packet p's triangles; returns the root box. The tree's own nodes, Woop
  // packets and bounds() stay as they are. movingOnly: as refitMoving(), only the moving nodes, when
  // keyNodes and keyVertices hold this tree's refit at positions that differ from these only in the
  // declared moving vertices (the sets then equal a full refit's bit for bit).
  Aabb refitKey(const float* positions, WideSoaNode<N>* keyNodes, KeyVertexPacket<N>* keyVertices, bool movingOnly,
                const ParallelFor& parallelFor);

  // Declares which vertices may move (ascending ids below vertexCount, as tsah::findMovingParts
  // takes them); refitMoving() then refits only the nodes whose subtree holds a triangle with such a
  // vertex. Throws tsah::DataError when an id or a triangle's vertex is at or past vertexCount.
  void setMovingVertices(std::span<const uint32_t> movingVertices, uint32_t vertexCount);
  // This frame's vertices when, since the last refit(), only the declared moving vertices changed:
  // the boxes and Woop packets of every node that moves; the others keep the last refit's, so the
  // tree equals refit()'s bit for bit. Without setMovingVertices: refit().
  void refitMoving(const float* positions, const ParallelFor& parallelFor);

  WideView<N> view(const uint32_t* indices, const float* positions) const;
  Aabb bounds() const { return rootBox_; }
  uint32_t depth() const { return depth_; }
  std::span<const WideSoaNode<N>> nodes() const { return nodes_; }
  TriangleForm form() const { return form_; }
  std::span<const WoopPacket<N>> packets() const { return packets_; }  // empty in the Vertices form
  std::span<const KeyVertexPacket<N>> vertexPackets() const { return vertexPackets_; }  // empty in the Woop form
  std::span<const uint32_t> packetSlots() const { return packetSlots_; }
  uint32_t packetCount() const { return uint32_t(packetSlots_.size()); }
  std::span<const uint32_t> triIndex() const { return triIndex_; }
  int32_t rootRef() const { return rootRef_; }
  uint32_t rootCount() const { return rootCount_; }

 private:
  // Where a refit writes: the boxes into `nodes` (the tree's own, or a key's), and the triangles
  // into `vertices` (a key's vertex packets, or the tree's own in the Vertices form), or into the
  // tree's Woop packets when `vertices` is null.
  struct Target {
    const float* positions;
    WideSoaNode<N>* nodes;
    KeyVertexPacket<N>* vertices;
  };
  Target ownTarget(const float* positions);  // the tree's own nodes and packets of its form
  // movingOnly (after setMovingVertices): the moving plan's nodes only. Returns the root box.
  Aabb refitTo(const Target& target, bool movingOnly, const ParallelFor& parallelFor);
  Aabb refitLeaf(uint32_t firstPacket, uint32_t count, const Target& target);
  // A refit task computes its nodes' leaf children first, in increasing packet order (so the
  // packet stores stream forward through memory), then their interior children, bottom-up.
  void refitLeaves(uint32_t node, const Target& target);
  void refitInterior(uint32_t node, WideSoaNode<N>* nodes);

  void (*woopRows_)(const float* positions, const uint32_t* vertices, uint32_t lanes, WoopPacket<N>& packet,
                    Aabb& bounds) = nullptr;
  void (*keyVertexRows_)(const float* positions, const uint32_t* vertices, uint32_t lanes, KeyVertexPacket<N>& out,
                         Aabb& bounds) = nullptr;
  // What a ray reads at every step in huge pages (TraversalVector).
  TraversalVector<WideSoaNode<N>> nodes_;
  TriangleForm form_ = TriangleForm::Woop;
  TraversalVector<WoopPacket<N>> packets_;             // the Woop form's
  TraversalVector<KeyVertexPacket<N>> vertexPackets_;  // the Vertices form's
  // The slot of each packet's lane 0 (its lanes hold consecutive slots): the refit and the vertex
  // leaf test read this instead of a Woop packet's own slot array, whose cache line would be a
  // cold miss per packet.
  std::vector<uint32_t> packetSlots_;
  std::vector<uint32_t> triIndex_;
  // The vertex indices of each slot's triangle (3 per slot): the refit reads them in slot order, a
  // stream, where indices[3 * triIndex[slot]] would be a cache miss per triangle.
  std::vector<uint32_t> slotVertices_;
  int32_t rootRef_ = makeLeafRef(0);
  uint32_t rootCount_ = 0;
  uint32_t depth_ = 0;
  Aabb rootBox_;
  std::vector<std::pair<uint32_t, uint32_t>> subtreeTasks_;
  std::vector<uint32_t> topNodes_;
  std::vector<uint32_t> subtreeEnds_;  // per node, one past its subtree's last node (pre-order)
  uint32_t threads_ = 1;               // the workers the refit plans are for
  std::shared_ptr<const detail::MovingRefitPlan> moving_;  // set by setMovingVertices
};

extern template class WideTree<4>;
extern template class WideTree<8>;

}  // namespace tsah
