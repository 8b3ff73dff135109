// CpuRuntime's motion blur (docs/motion-blur.md): the current tree refitted at every key of a
// shutter, one node set, root box and position set (and in the wide layouts one vertex packet set)
// kept per key; keys the previous shutter already had are reused.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "tsah/base/error.hpp"
#include "tsah/base/memory.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/runtime/cpu_runtime.hpp"

namespace tsah {

void CpuRuntime::clearShutter() {
  keysRefitted_ = 0;
  keysRefittedMovingOnly_ = 0;
  keyTimes_.clear();
  keyNodes_.clear();
  keyRootBoxes_.clear();
  keyPositions_.clear();
  keyWide4_.clear();
  keyWide8_.clear();
  segments4_.clear();
  segments8_.clear();
  motionView_ = MotionBvhView{};
}

template <uint32_t N>
void CpuRuntime::setSegments(const WideView<N>& view, const std::vector<WideKey<N>>& keys,
                             std::vector<WideSegment<N>>& out) {
  out.resize(keys.size() - 1);
  for (std::size_t s = 0; s + 1 < keys.size(); ++s) {
    WideSegment<N>& seg = out[s];
    seg.view = view;
    seg.view.nodes = keys[s].nodes.data();
    seg.view.positions = keyPositions_.data() + s * std::size_t(vertexCount_) * 3;
    seg.motion.nodes1 = keys[s + 1].nodes.data();
    seg.motion.vertices0 = keys[s].vertices.data();
    seg.motion.vertices1 = keys[s + 1].vertices.data();
    seg.motion.rootBounds = motion::segmentBounds(keyRootBoxes_[s], keyRootBoxes_[s + 1]);
  }
}

template <uint32_t N, class Trace>
auto CpuRuntime::traceSegment(const std::vector<WideSegment<N>>& segments, float time, const Trace& trace) const {
  const motion::Segment seg = motion::segmentAt(keyTimes_.data(), int(keyTimes_.size()), time);
  const WideSegment<N>& frame = segments[std::size_t(seg.index)];
  WideMotionFrame<N> m = frame.motion;
  m.f = seg.f;
  if (!isLeafRef(frame.view.rootRef)) return trace(frame.view, m);
  // The kernels test the root box of a leaf root only (an interior root's children are tested).
  WideView<N> v = frame.view;
  v.rootBox = motion::lerpBox(keyRootBoxes_[std::size_t(seg.index)], keyRootBoxes_[std::size_t(seg.index) + 1], seg.f);
  return trace(v, m);
}

namespace {

bool sameBits(std::span<const float> a, std::span<const float> b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size_bytes()) == 0;
}

// One key's block of a per-key array (keys of `size` elements each).
template <class T>
std::span<T> keyBlock(std::vector<T>& sets, std::size_t key, std::size_t size) {
  return std::span<T>(sets).subspan(key * size, size);
}

// The wide sets of the next shutter's keys (reused[k]: the old key that new key k reuses, or
// old.size() when it is refitted): a reused key's set is moved (copied when two new keys reuse it),
// and the old sets no key reuses go to the keys to refit as their buffers.
template <class WideKey>
std::vector<WideKey> passOnWideKeys(std::vector<WideKey>& old, const std::vector<std::size_t>& reused) {
  std::vector<WideKey> next(reused.size());
  std::vector<std::size_t> movedTo(old.size(), reused.size());
  for (std::size_t k = 0; k < reused.size(); ++k) {
    const std::size_t j = reused[k];
    if (j == old.size()) continue;
    if (movedTo[j] < reused.size()) {
      next[k] = next[movedTo[j]];
    } else {
      next[k] = std::move(old[j]);
      movedTo[j] = k;
    }
  }
  std::size_t spare = 0;
  for (std::size_t k = 0; k < reused.size(); ++k) {
    if (reused[k] != old.size()) continue;
    while (spare < old.size() && movedTo[spare] < reused.size()) ++spare;
    if (spare == old.size()) break;
    next[k] = std::move(old[spare++]);
  }
  return next;
}

}  // namespace

// The refit of the current tree at one key (its positions already checked) into the key's blocks:
// its positions, the boxes, and in a wide layout the key's vertex packets (no Woop rows: a blurred
// frame reads none). With Config::movingVertices a key set that holds a refit of this tree (bvh2:
// the runtime's own tree, whose refit each key runs on) refits only the moving nodes: the static
// vertices are the same at every key.
void CpuRuntime::refitShutterKey(std::span<const float> positions, bool readMovingOnly, ShutterKeys& out,
                                 std::size_t key) {
  const std::span<float> block = keyBlock(out.positions, key, positions.size());
  if (readMovingOnly) {
    std::copy(positions_.begin(), positions_.end(), block.begin());
    for (uint32_t v : *movingVertices_)
      std::copy_n(positions.begin() + 3 * std::ptrdiff_t(v), 3, block.begin() + 3 * std::ptrdiff_t(v));
  } else {
    std::copy(positions.begin(), positions.end(), block.begin());
  }
  const auto parallel = [this](std::size_t n, const std::function<void(std::size_t, std::size_t)>& body) {
    parallelFor(n, 1, body);
  };
  const auto wideKey = [&](auto& tree, auto& set) {
    const bool movingOnly = set.refitted && movingVertices_.has_value();
    if (!set.refitted) {  // a new key set, or a dropped one of another size: the tree's refs and counts
      set.nodes.assign(tree.nodes().begin(), tree.nodes().end());
      set.vertices.resize(tree.packets().size());
    }
    out.rootBoxes[key] = tree.refitKey(block.data(), set.nodes.data(), set.vertices.data(), movingOnly, parallel);
    set.refitted = true;
    return movingOnly;
  };
  bool movingOnly = false;
  if (wide4_) {
    movingOnly = wideKey(*wide4_, out.wide4[key]);
  } else if (wide8_) {
    movingOnly = wideKey(*wide8_, out.wide8[key]);
  } else {
    movingOnly = staticRefitted_;  // the tree's last full refit is this tree's
    positions_.assign(block.begin(), block.end());
    refitAndWoop(movingOnly);
    staticRefitted_ = movingVertices_.has_value();
    std::copy_n(tree_.nodes.begin(), tree_.interiorCount, keyBlock(out.nodes, key, tree_.interiorCount).begin());
    out.rootBoxes[key] = tree_.rootBoxes[0];
  }
  keysRefittedMovingOnly_ += movingOnly ? 1 : 0;
}

void CpuRuntime::updateShutter(std::span<const float> keyTimes,
                               std::span<const std::span<const float>> keyPositions) {
  motion::checkKeyTimes(keyTimes, keyPositions.size(), "runtime: ");
  if (keyTimes.size() == 1) {
    update(keyPositions[0]);
    return;
  }
  const std::size_t keys = keyTimes.size();
  const std::size_t floats = std::size_t(vertexCount_) * 3;
  for (std::size_t k = 0; k < keys; ++k)
    if (keyPositions[k].size() != floats)
      throw tsah::DataError("runtime: key " + std::to_string(k) + " has " + std::to_string(keyPositions[k].size()) +
                            " coordinates, expected " + std::to_string(floats));
  const std::size_t nodeBytes = wide4_   ? wide4_->nodes().size() * sizeof(WideSoaNode<4>)
                                : wide8_ ? wide8_->nodes().size() * sizeof(WideSoaNode<8>)
                                         : tree_.interiorCount * sizeof(GpuBvhNode);
  const std::size_t vertexBytes = wide4_   ? wide4_->packets().size() * sizeof(KeyVertexPacket<4>)
                                  : wide8_ ? wide8_->packets().size() * sizeof(KeyVertexPacket<8>)
                                           : 0;
  checkFitsInMemory(keys * (nodeBytes + vertexBytes + floats * sizeof(float) + sizeof(Aabb)), "runtime",
                    "a shutter of " + std::to_string(keys) + " keys");
  // A key whose positions equal, bit for bit, a key of the previous shutter keeps that key's refit
  // (consecutive frames whose shutters meet share the key between them): the refit is a function
  // of the tree and the positions, and the tree has not changed since (a tree change clears the
  // shutter).
  // With Config::movingVertices, once positions were read in full, the keys' static vertices are
  // those positions: only the moving ones are read, compared and checked.
  const bool readMovingOnly = movingVertices_.has_value() && staticPositionsRead_;
  const auto sameKey = [&](std::span<const float> given, std::size_t old) {
    const std::span<const float> kept = std::span<const float>(keyPositions_).subspan(old * floats, floats);
    if (!readMovingOnly) return sameBits(given, kept);
    for (uint32_t v : *movingVertices_)
      if (std::memcmp(given.data() + 3 * std::size_t(v), kept.data() + 3 * std::size_t(v), 3 * sizeof(float)) != 0)
        return false;
    return true;
  };
  const std::size_t oldKeys = keyTimes_.size();
  std::vector<std::size_t> reused(keys, oldKeys);
  for (std::size_t k = 0; k < keys; ++k)
    for (std::size_t j = 0; j < oldKeys; ++j)
      if (sameKey(keyPositions[k], j)) {
        reused[k] = j;
        break;
      }
  // Every key to refit is checked first, so that an error leaves the runtime as it was.
  for (std::size_t k = 0; k < keys; ++k)
    if (reused[k] == oldKeys) readMovingOnly ? checkMovingPositions(keyPositions[k]) : checkPositions(keyPositions[k]);
  ShutterKeys next;
  next.nodes.resize(wide4_ || wide8_ ? 0 : keys * tree_.interiorCount);
  next.rootBoxes.resize(keys);
  // Into the buffer of the shutter before last (a fresh one would be zeroed and faulted in, per frame).
  next.positions = std::move(spareKeyPositions_);
  next.positions.resize(keys * floats);
  if (wide4_) next.wide4 = passOnWideKeys(keyWide4_, reused);
  if (wide8_) next.wide8 = passOnWideKeys(keyWide8_, reused);
  uint32_t refitted = 0;
  keysRefittedMovingOnly_ = 0;
  for (std::size_t k = 0; k < keys; ++k) {
    if (reused[k] < oldKeys) {
      copyShutterKey(reused[k], next, k);
    } else {
      refitShutterKey(keyPositions[k], readMovingOnly, next, k);
      ++refitted;
    }
  }
  // The runtime's positions are the last key's (the renderer's smooth normals read them).
  if (const std::span<const float> last = keyBlock(next.positions, keys - 1, floats); !sameBits(positions_, last))
    positions_.assign(last.begin(), last.end());
  staticPositionsRead_ = true;
  keysRefitted_ = refitted;
  keyTimes_.assign(keyTimes.begin(), keyTimes.end());
  keyNodes_ = std::move(next.nodes);
  keyRootBoxes_ = std::move(next.rootBoxes);
  spareKeyPositions_ = std::move(keyPositions_);
  keyPositions_ = std::move(next.positions);
  keyWide4_ = std::move(next.wide4);
  keyWide8_ = std::move(next.wide8);
  // The wide view's tree fields (root, packets' slots, triangle ids) for the segments, also when no
  // update() came before.
  if (wide4_) {
    view4_ = wide4_->view(indices_.data(), positions_.data());
    setSegments(view4_, keyWide4_, segments4_);
  }
  if (wide8_) {
    view8_ = wide8_->view(indices_.data(), positions_.data());
    setSegments(view8_, keyWide8_, segments8_);
  }
  // The key positions, times and triangles in every layout (the renderer's blurred surfaces read
  // them); the binary key nodes in bvh2 only.
  const bool wide = wide4_ || wide8_;
  MotionBvhView& v = motionView_;
  v.keyNodes = wide ? nullptr : keyNodes_.data();
  v.keyRootBoxes = keyRootBoxes_.data();
  v.keyPositions = keyPositions_.data();
  v.keyTimes = keyTimes_.data();
  v.keyCount = uint32_t(keys);
  v.nodeCount = wide ? 0u : tree_.interiorCount;
  v.vertexCount = vertexCount_;
  v.triIndex = tree_.triIndex.data();
  v.indices = indices_.data();
  v.rootRef = tree_.rootRef;
  v.rootCount = tree_.rootCount;
}

// Key `from` of the current shutter into key `to` of the next: its positions, root box and
// binary nodes (the wide sets are passed on by passOnWideKeys).
void CpuRuntime::copyShutterKey(std::size_t from, ShutterKeys& next, std::size_t to) const {
  const std::size_t keys = keyTimes_.size();
  const auto copy = [&](const auto& sets, auto& into) {
    if (sets.empty()) return;
    const std::size_t size = sets.size() / keys;
    std::copy_n(sets.begin() + std::ptrdiff_t(from * size), size, into.begin() + std::ptrdiff_t(to * size));
  };
  copy(keyNodes_, next.nodes);
  copy(keyPositions_, next.positions);
  next.rootBoxes[to] = keyRootBoxes_[from];
}

Hit CpuRuntime::closestHit(const Ray& ray, float time) const {
  if (!blurred()) return closestHit(ray);
  if (wide8_)
    return traceSegment(segments8_, time, [&](const auto& v, const auto& m) { return kernels_->closestMotion8(v, m, ray); });
  if (wide4_)
    return traceSegment(segments4_, time, [&](const auto& v, const auto& m) { return kernels_->closestMotion4(v, m, ray); });
  return tsah::closestHit(motionView_, ray, time);
}

bool CpuRuntime::anyHit(const Ray& ray, float time, AnyHitOrder order) const {
  if (!blurred()) return anyHit(ray, order);
  if (wide8_)
    return traceSegment(segments8_, time, [&](const auto& v, const auto& m) { return kernels_->anyMotion8(v, m, ray, order); });
  if (wide4_)
    return traceSegment(segments4_, time, [&](const auto& v, const auto& m) { return kernels_->anyMotion4(v, m, ray, order); });
  return tsah::anyHit(motionView_, ray, time);
}

}  // namespace tsah
