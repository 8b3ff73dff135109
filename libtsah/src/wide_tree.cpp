#include "tsah/wide_tree.hpp"

#include <cstring>

#include "anim/error.hpp"
#include "refit_plan.hpp"

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

}  // namespace

template <uint32_t N>
WideTree<N>::WideTree(const WideBvh& w, uint32_t threads) {
  if (w.width > N)
    throw anim::Error("wide tree: a " + std::to_string(w.width) + "-wide topology does not fit " + std::to_string(N) +
                      "-wide nodes");
  if (auto problem = validateWide(w)) throw anim::Error("wide tree: invalid topology: " + *problem);
  depth_ = w.depth();
  if (wideStackNeed<N>(depth_) > kWideStackSize)
    throw anim::Error("wide tree: depth " + std::to_string(depth_) + " exceeds the traversal stack");
  triIndex_ = w.primIds;
  // Packets of a leaf over slots [first, first + count): lane l of packet p holds slot first + p*N + l.
  auto addLeaf = [&](uint32_t first, uint32_t count) {
    const auto packet = static_cast<uint32_t>(packets_.size());
    for (uint32_t p = 0; p < packetCount<N>(count); ++p) {
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
  detail::planParallelRefit(
      wideSubtreeEnds(w), threads,
      [&](uint32_t i, auto push) {
        for (uint32_t c = 0; c < N; ++c)
          if (usedSlot(nodes_[i], c) && !isLeafRef(nodes_[i].ref[c])) push(static_cast<uint32_t>(nodes_[i].ref[c]));
      },
      subtreeTasks_, topNodes_);
}

template <uint32_t N>
Aabb WideTree<N>::refitLeaf(uint32_t firstPacket, uint32_t count, const float* p, const uint32_t* indices) {
  Aabb box;
  for (uint32_t i = 0; i < count; ++i) {
    WoopPacket<N>& pk = packets_[firstPacket + i / N];
    const uint32_t slot = pk.slot[i % N];
    const uint32_t* tri = indices + 3 * std::size_t(triIndex_[slot]);
    const Vec3 v0{p[3 * tri[0]], p[3 * tri[0] + 1], p[3 * tri[0] + 2]};
    const Vec3 v1{p[3 * tri[1]], p[3 * tri[1] + 1], p[3 * tri[1] + 2]};
    const Vec3 v2{p[3 * tri[2]], p[3 * tri[2] + 1], p[3 * tri[2] + 2]};
    pk.set(i % N, makeWoopTriangle(v0, v1, v2), slot);
    box.extend(v0);
    box.extend(v1);
    box.extend(v2);
  }
  return box;
}

template <uint32_t N>
void WideTree<N>::refitNode(uint32_t i, const float* positions, const uint32_t* indices) {
  WideSoaNode<N>& node = nodes_[i];
  for (uint32_t c = 0; c < N && usedSlot(node, c); ++c) {
    const int32_t ref = node.ref[c];
    node.setChildBox(c, isLeafRef(ref) ? refitLeaf(leafFirstSlot(ref), node.count[c], positions, indices)
                                       : nodes_[static_cast<uint32_t>(ref)].bounds());
  }
}

template <uint32_t N>
void WideTree<N>::refit(const float* positions, const uint32_t* indices, const ParallelFor& parallelFor) {
  if (isLeafRef(rootRef_)) {
    rootBox_ = refitLeaf(leafFirstSlot(rootRef_), rootCount_, positions, indices);
    return;
  }
  parallelFor(subtreeTasks_.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t < end; ++t) {
      const auto [root, stop] = subtreeTasks_[t];
      for (uint32_t i = stop; i-- > root;) refitNode(i, positions, indices);  // children (larger indices) first
    }
  });
  for (uint32_t i : topNodes_) refitNode(i, positions, indices);
  rootBox_ = nodes_[0].bounds();
}

template <uint32_t N>
WideView<N> WideTree<N>::view(const uint32_t* indices, const float* positions) const {
  WideView<N> v;
  v.nodes = nodes_.data();
  v.packets = packets_.data();
  v.triIndex = triIndex_.data();
  v.indices = indices;
  v.positions = positions;
  v.rootRef = rootRef_;
  v.rootCount = rootCount_;
  v.rootBox = rootBox_;
  return v;
}

template class WideTree<4>;
template class WideTree<8>;

}  // namespace tsah
