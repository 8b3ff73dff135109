#include "tsah/layout/wide_tree.hpp"

#include <cstring>

#include "tsah/base/error.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "layout/refit_plan.hpp"

namespace tsah {

namespace {

template <uint32_t N>
void clearNode(WideSoaNode<N>& node) {
  for (uint32_t c = 0; c < N; ++c) {
    node.setChildBox(c, Aabb{});  // the empty box: never entered (wide_layout.hpp)
    node.ref[c] = 0;
    node.count[c] = 0;
  }
}

// An unused slot: ref 0 (the root, never anyone's child) with no triangles.
template <uint32_t N>
bool usedSlot(const WideSoaNode<N>& node, uint32_t c) {
  return node.ref[c] != 0 || node.count[c] != 0;
}

// The refit planners' view of the tree: push(c) for every interior child c of node i.
template <uint32_t N>
auto interiorChildrenOf(std::span<const WideSoaNode<N>> nodes) {
  return [nodes](uint32_t i, auto push) {
    for (uint32_t c = 0; c < N; ++c)
      if (usedSlot(nodes[i], c) && !isLeafRef(nodes[i].ref[c])) push(static_cast<uint32_t>(nodes[i].ref[c]));
  };
}

}  // namespace

template <uint32_t N>
WideTree<N>::WideTree(const WideBvh& w, std::span<const uint32_t> indices, uint32_t threads, SimdIsa isa,
                      TriangleForm form)
    : form_(form) {
  if constexpr (N == 4) {
    woopRows_ = wideKernels(isa).woopRows4;
    keyVertexRows_ = wideKernels(isa).keyVertices4;
  } else {
    woopRows_ = wideKernels(isa).woopRows8;
    keyVertexRows_ = wideKernels(isa).keyVertices8;
  }
  if (w.width > N)
    throw tsah::DataError("wide tree: a " + std::to_string(w.width) + "-wide topology does not fit " +
                          std::to_string(N) + "-wide nodes");
  if (auto problem = validateWide(w)) throw tsah::DataError("wide tree: invalid topology: " + *problem);
  depth_ = w.depth();
  if (wideStackNeed<N>(depth_) > kWideStackSize)
    throw tsah::DataError("wide tree: depth " + std::to_string(depth_) + " exceeds the traversal stack");
  triIndex_ = w.primIds;
  slotVertices_ = slotVertexIndices(triIndex_, indices, "wide tree");
  // Packets of a leaf over slots [first, first + count): lane l of packet p holds slot first + p*N + l.
  auto addLeaf = [&](uint32_t first, uint32_t count) {
    const auto packet = static_cast<uint32_t>(packetSlots_.size());
    for (uint32_t p = 0; p < tsah::packetCount<N>(count); ++p) {
      packetSlots_.push_back(first + p * N);
      if (form_ == TriangleForm::Vertices) {
        vertexPackets_.emplace_back();  // filled by every refit
        continue;
      }
      WoopPacket<N> pk;
      std::memset(&pk, 0, sizeof pk);
      for (uint32_t lane = 0; lane < N; ++lane) pk.slot[lane] = p * N + lane < count ? first + p * N + lane : first;
      packets_.push_back(pk);
    }
    return makeLeafRef(packet);
  };
  if (isLeafRef(w.rootRef)) {
    rootRef_ = addLeaf(0, w.rootCount);
    rootCount_ = w.rootCount;
    return;
  }
  rootRef_ = 0;
  nodes_.resize(w.nodeCount());
  for (uint32_t n = 0; n < w.nodeCount(); ++n) {
    WideSoaNode<N>& node = nodes_[n];
    clearNode(node);
    for (uint32_t c = 0; c < w.nodes[n].childCount; ++c) {
      const WideChild& child = w.children[w.nodes[n].firstChild + c];
      node.ref[c] = child.isLeaf() ? addLeaf(child.firstPrim(), child.count) : child.ref;
      node.count[c] = child.isLeaf() ? child.count : 0;
    }
  }
  threads_ = threads;
  subtreeEnds_ = wideSubtreeEnds(w);
  detail::planParallelRefit(subtreeEnds_, threads, interiorChildrenOf<N>(nodes_), subtreeTasks_, topNodes_,
                            64 / N);  // a wide node: about N / 2 binary nodes' triangles and boxes
}

template <uint32_t N>
Aabb WideTree<N>::refitLeaf(uint32_t firstPacket, uint32_t count, const Target& target) {
  Aabb box;
  for (uint32_t first = 0; first < count; first += N) {
    const uint32_t packet = firstPacket + first / N;
    const uint32_t lanes = count - first < N ? count - first : N;
    const uint32_t* vertices = slotVertices_.data() + 3 * std::size_t(packetSlots_[packet]);
    Aabb packetBox;  // rows and box of all lanes at once, in SIMD (both kernels give the same box)
    if (target.vertices)
      keyVertexRows_(target.positions, vertices, lanes, target.vertices[packet], packetBox);
    else
      woopRows_(target.positions, vertices, lanes, packets_[packet], packetBox);
    box.extend(packetBox);
  }
  return box;
}

namespace {

// The union of a node's children (unused slots hold the empty box), lane by lane.
template <uint32_t N>
Aabb nodeBounds(const WideSoaNode<N>& node) {
  float b[6];
  for (int r = 0; r < 3; ++r) {
    float lo = node.box[r][0], hi = node.box[r + 3][0];
    for (uint32_t c = 1; c < N; ++c) {
      lo = node.box[r][c] < lo ? node.box[r][c] : lo;
      hi = node.box[r + 3][c] > hi ? node.box[r + 3][c] : hi;
    }
    b[r] = lo;
    b[r + 3] = hi;
  }
  Aabb box;
  box.lo = {b[0], b[1], b[2]};
  box.hi = {b[3], b[4], b[5]};
  return box;
}

}  // namespace

template <uint32_t N>
void WideTree<N>::refitLeaves(uint32_t i, const Target& target) {
  WideSoaNode<N>& node = target.nodes[i];
  for (uint32_t c = 0; c < N && usedSlot(node, c); ++c)
    if (isLeafRef(node.ref[c])) node.setChildBox(c, refitLeaf(leafFirstSlot(node.ref[c]), node.count[c], target));
}

template <uint32_t N>
void WideTree<N>::refitInterior(uint32_t i, WideSoaNode<N>* nodes) {
  WideSoaNode<N>& node = nodes[i];
  for (uint32_t c = 0; c < N && usedSlot(node, c); ++c)
    if (!isLeafRef(node.ref[c])) node.setChildBox(c, nodeBounds(nodes[static_cast<uint32_t>(node.ref[c])]));
}

template <uint32_t N>
typename WideTree<N>::Target WideTree<N>::ownTarget(const float* positions) {
  return {positions, nodes_.data(), form_ == TriangleForm::Vertices ? vertexPackets_.data() : nullptr};
}

template <uint32_t N>
void WideTree<N>::refit(const float* positions, const ParallelFor& parallelFor) {
  rootBox_ = refitTo(ownTarget(positions), false, parallelFor);
}

template <uint32_t N>
void WideTree<N>::refitMoving(const float* positions, const ParallelFor& parallelFor) {
  rootBox_ = refitTo(ownTarget(positions), true, parallelFor);
}

template <uint32_t N>
Aabb WideTree<N>::refitKey(const float* positions, WideSoaNode<N>* keyNodes, KeyVertexPacket<N>* keyVertices,
                           bool movingOnly, const ParallelFor& parallelFor) {
  return refitTo({positions, keyNodes, keyVertices}, movingOnly, parallelFor);
}

template <uint32_t N>
Aabb WideTree<N>::refitTo(const Target& target, bool movingOnly, const ParallelFor& parallelFor) {
  if (isLeafRef(rootRef_)) return refitLeaf(leafFirstSlot(rootRef_), rootCount_, target);
  if (movingOnly && moving_) {
    const detail::MovingRefitPlan& plan = *moving_;
    parallelFor(plan.taskCount(), [&](std::size_t begin, std::size_t end) {
      for (std::size_t t = begin; t < end; ++t) {
        const uint32_t first = plan.taskStart[t], stop = plan.taskStart[t + 1];
        for (uint32_t k = first; k < stop; ++k) refitLeaves(plan.taskNodes[k], target);
        for (uint32_t k = stop; k-- > first;) refitInterior(plan.taskNodes[k], target.nodes);  // children first
      }
    });
    for (uint32_t i : plan.top) refitLeaves(i, target), refitInterior(i, target.nodes);
  } else {
    parallelFor(subtreeTasks_.size(), [&](std::size_t begin, std::size_t end) {
      for (std::size_t t = begin; t < end; ++t) {
        const auto [root, stop] = subtreeTasks_[t];
        for (uint32_t i = root; i < stop; ++i) refitLeaves(i, target);        // packets in memory order
        for (uint32_t i = stop; i-- > root;) refitInterior(i, target.nodes);  // children (larger indices) first
      }
    });
    for (uint32_t i : topNodes_) refitLeaves(i, target), refitInterior(i, target.nodes);
  }
  return nodeBounds(target.nodes[0]);
}

template <uint32_t N>
void WideTree<N>::setMovingVertices(std::span<const uint32_t> movingVertices, uint32_t vertexCount) {
  std::vector<uint8_t> vertexMoves(vertexCount, 0);
  for (uint32_t v : movingVertices) {
    if (v >= vertexCount) throw tsah::DataError("wide tree: a moving vertex id is out of range");
    vertexMoves[v] = 1;
  }
  for (uint32_t v : slotVertices_)
    if (v >= vertexCount) throw tsah::DataError("wide tree: a triangle refers to a vertex out of range");
  const auto leafMoves = [&](int32_t ref, uint32_t count) {
    const uint32_t firstPacket = leafFirstSlot(ref);
    for (uint32_t k = 0; k < count; ++k) {
      const uint32_t* tri = slotVertices_.data() + 3 * std::size_t(packetSlots_[firstPacket + k / N] + k % N);
      if (vertexMoves[tri[0]] | vertexMoves[tri[1]] | vertexMoves[tri[2]]) return true;
    }
    return false;
  };
  // Pre-order: every child after its parent, so one descending pass sees the children first.
  std::vector<uint8_t> nodeMoves(nodes_.size(), 0);
  for (uint32_t i = uint32_t(nodes_.size()); i-- > 0;) {
    const WideSoaNode<N>& node = nodes_[i];
    for (uint32_t c = 0; c < N && usedSlot(node, c) && !nodeMoves[i]; ++c)
      nodeMoves[i] = isLeafRef(node.ref[c]) ? leafMoves(node.ref[c], node.count[c])
                                            : nodeMoves[static_cast<uint32_t>(node.ref[c])];
  }
  moving_ = std::make_shared<const detail::MovingRefitPlan>(
      detail::planMovingRefit(subtreeEnds_, threads_, interiorChildrenOf<N>(nodes_), nodeMoves, 16 / N));
}

template <uint32_t N>
WideView<N> WideTree<N>::view(const uint32_t* indices, const float* positions) const {
  WideView<N> v;
  v.nodes = nodes_.data();
  v.packets = form_ == TriangleForm::Woop ? packets_.data() : nullptr;
  v.vertexPackets = form_ == TriangleForm::Vertices ? vertexPackets_.data() : nullptr;
  v.packetSlots = packetSlots_.data();
  v.triIndex = triIndex_.data();
  v.indices = indices;
  v.slotVertices = slotVertices_.data();
  v.positions = positions;
  v.rootRef = rootRef_;
  v.rootCount = rootCount_;
  v.rootBox = rootBox_;
  return v;
}

template class WideTree<4>;
template class WideTree<8>;

}  // namespace tsah
