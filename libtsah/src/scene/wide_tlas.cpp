#include "wide_tlas.hpp"

#include <array>

namespace tsah::detail {

// A binary subtree not yet placed: an interior node of the binary TLAS (ref >= 0), or a range of
// its slots (ref < 0: a binary leaf, or part of one).
template <uint32_t N>
struct WideTlas<N>::Candidate {
  int32_t ref = -1;
  uint32_t first = 0, count = 0;
  Aabb box;
  bool splittable() const { return ref >= 0 || count > 1; }
};

namespace {

Aabb rangeBox(const FlatBvh& tlas, std::span<const Aabb> instanceBoxes, uint32_t first, uint32_t count) {
  Aabb box;
  for (uint32_t s = first; s < first + count; ++s) box.extend(instanceBoxes[tlas.triIndex[s]]);
  return box;
}

float openingArea(const Aabb& box) { return box.empty() ? 0.0f : box.area(); }

}  // namespace

template <uint32_t N>
int32_t WideTlas<N>::build(const Candidate& c, const FlatBvh& tlas, std::span<const Aabb> instanceBoxes) {
  const auto split = [&](const Candidate& parent) {
    std::array<Candidate, 2> two;
    if (parent.ref >= 0) {
      const GpuBvhNode& node = tlas.nodes[uint32_t(parent.ref)];
      for (int k = 0; k < 2; ++k) {
        const int32_t ref = node.childRef(k);
        two[k] = isLeafRef(ref) ? Candidate{-1, leafFirstSlot(ref), node.childCount(k), node.childBox(k)}
                                : Candidate{ref, 0, 0, node.childBox(k)};
      }
    } else {
      const uint32_t half = parent.count / 2;
      two[0] = {-1, parent.first, half, rangeBox(tlas, instanceBoxes, parent.first, half)};
      two[1] = {-1, parent.first + half, parent.count - half,
                rangeBox(tlas, instanceBoxes, parent.first + half, parent.count - half)};
    }
    return two;
  };
  const uint32_t index = uint32_t(nodes_.size());
  nodes_.emplace_back();
  used_.push_back(0);
  const std::array<Candidate, 2> first = split(c);
  std::vector<Candidate> open(first.begin(), first.end());
  while (open.size() < N) {
    std::size_t best = open.size();
    for (std::size_t i = 0; i < open.size(); ++i)
      if (open[i].splittable() && (best == open.size() || openingArea(open[i].box) > openingArea(open[best].box)))
        best = i;
    if (best == open.size()) break;
    const std::array<Candidate, 2> two = split(open[best]);
    open[best] = two[0];
    open.insert(open.begin() + std::ptrdiff_t(best) + 1, two[1]);
  }
  WideSoaNode<N> node{};
  for (uint32_t k = 0; k < N; ++k) node.setChildBox(k, Aabb{});  // unused slots: the empty box
  for (std::size_t k = 0; k < open.size(); ++k) {
    if (open[k].splittable()) {
      node.ref[k] = build(open[k], tlas, instanceBoxes);  // nodes_ may move: written below by index
    } else {
      node.ref[k] = makeLeafRef(tlas.triIndex[open[k].first]);
      node.count[k] = 1;
    }
  }
  nodes_[index] = node;
  used_[index] = uint8_t(open.size());
  return int32_t(index);
}

template <uint32_t N>
WideTlas<N>::WideTlas(const FlatBvh& tlas, std::span<const Aabb> instanceBoxes) {
  Candidate root{tlas.rootRef, 0, 0, tlas.rootBoxes.empty() ? Aabb{} : tlas.rootBoxes[0]};
  if (isLeafRef(tlas.rootRef)) root = {-1, leafFirstSlot(tlas.rootRef), tlas.rootCount, root.box};
  if (root.splittable()) {
    rootRef_ = build(root, tlas, instanceBoxes);
    rootCount_ = 0;
  } else {  // one instance
    rootRef_ = makeLeafRef(tlas.triIndex[root.first]);
    rootCount_ = 1;
  }
}

template <uint32_t N>
void WideTlas<N>::refit(std::span<const Aabb> instanceBoxes) {
  for (std::size_t i = nodes_.size(); i-- > 0;) {  // children come after their parents
    WideSoaNode<N>& node = nodes_[i];
    for (uint32_t k = 0; k < used_[i]; ++k)
      node.setChildBox(k, node.count[k] == 1 ? instanceBoxes[leafFirstSlot(node.ref[k])]
                                             : nodes_[uint32_t(node.ref[k])].bounds());
  }
  rootBox_ = rootCount_ == 1 ? instanceBoxes[leafFirstSlot(rootRef_)] : nodes_[0].bounds();
}

template <uint32_t N>
WideView<N> WideTlas<N>::view() const {
  WideView<N> v;
  v.nodes = nodes_.data();
  v.rootRef = rootRef_;
  v.rootCount = rootCount_;
  v.rootBox = rootBox_;
  return v;
}

template class WideTlas<4>;
template class WideTlas<8>;

}  // namespace tsah::detail
