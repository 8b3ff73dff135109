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
  if (!parts_.empty()) spareKeyPositions_ = std::move(parts_.back().keyPositions);
  parts_.clear();
}

std::size_t CpuRuntime::partAt(float time) const {
  std::size_t p = 0;
  while (p + 1 < parts_.size() && parts_[p + 1].keyTimes.front() <= time) ++p;
  return p;
}

uint32_t CpuRuntime::shutterKeyCount() const {
  std::size_t keys = 0;
  for (const BlurredPart& part : parts_) keys += part.keyTimes.size();
  return static_cast<uint32_t>(keys);
}

const MotionBvhView& CpuRuntime::motionView(std::size_t part) const {
  static const MotionBvhView kNotBlurred{};
  return part < parts_.size() ? parts_[part].view : kNotBlurred;
}

template <uint32_t N>
void CpuRuntime::setSegments(const WideView<N>& view, BlurredPart& part, std::vector<WideKey<N>> BlurredPart::*keySets,
                             std::vector<WideSegment<N>> BlurredPart::*segmentSets) {
  const std::vector<WideKey<N>>& keys = part.*keySets;
  std::vector<WideSegment<N>>& out = part.*segmentSets;
  out.resize(keys.size() - 1);
  for (std::size_t s = 0; s + 1 < keys.size(); ++s) {
    WideSegment<N>& seg = out[s];
    seg.view = view;
    seg.view.nodes = keys[s].nodes.data();
    seg.view.positions = part.keyPositions.data() + s * std::size_t(vertexCount_) * 3;
    seg.motion.nodes1 = keys[s + 1].nodes.data();
    seg.motion.vertices0 = keys[s].vertices.data();
    seg.motion.vertices1 = keys[s + 1].vertices.data();
    seg.motion.rootBounds = motion::segmentBounds(part.keyRootBoxes[s], part.keyRootBoxes[s + 1]);
  }
}

template <uint32_t N, class Trace>
auto CpuRuntime::traceSegment(const BlurredPart& part, const std::vector<WideSegment<N>>& segments, float time,
                              const Trace& trace) const {
  const motion::Segment seg = motion::segmentAt(part.keyTimes.data(), int(part.keyTimes.size()), time);
  const WideSegment<N>& frame = segments[std::size_t(seg.index)];
  WideMotionFrame<N> m = frame.motion;
  m.f = seg.f;
  if (!isLeafRef(frame.view.rootRef)) return trace(frame.view, m);
  // The kernels test the root box of a leaf root only (an interior root's children are tested).
  WideView<N> v = frame.view;
  const std::size_t s = std::size_t(seg.index);
  v.rootBox = motion::lerpBox(part.keyRootBoxes[s], part.keyRootBoxes[s + 1], seg.f);
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
void CpuRuntime::refitShutterKey(std::span<const float> positions, bool readMovingOnly, BlurredPart& out,
                                 std::size_t key) {
  const std::span<float> block = keyBlock(out.keyPositions, key, positions.size());
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
      set.vertices.resize(tree.packetCount());
    }
    out.keyRootBoxes[key] = tree.refitKey(block.data(), set.nodes.data(), set.vertices.data(), movingOnly, parallel);
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
    std::copy_n(tree_.nodes.begin(), tree_.interiorCount, keyBlock(out.keyNodes, key, tree_.interiorCount).begin());
    out.keyRootBoxes[key] = tree_.rootBoxes[0];
  }
  keysRefittedMovingOnly_ += movingOnly ? 1 : 0;
}

void CpuRuntime::updateShutter(std::span<const float> keyTimes,
                               std::span<const std::span<const float>> keyPositions) {
  const ShutterPart part{current_, keyTimes, keyPositions};
  updateShutter(std::span<const ShutterPart>(&part, 1));
}

namespace {

// The parts' rules (cpu_runtime.hpp), then motion::checkKeyTimes on the key times of the whole
// shutter (each part's first key after the first part's left out), which it returns.
std::vector<float> checkedPartTimes(std::span<const CpuRuntime::ShutterPart> parts, uint32_t trees) {
  if (parts.empty()) throw tsah::ConfigError("runtime: a shutter needs at least one part");
  if (parts.size() == 1) {
    motion::checkKeyTimes(parts[0].keyTimes, parts[0].keyPositions.size(), "runtime: ");
    return {parts[0].keyTimes.begin(), parts[0].keyTimes.end()};
  }
  std::vector<float> times;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    const CpuRuntime::ShutterPart& part = parts[p];
    const std::string name = "runtime: shutter part " + std::to_string(p);
    if (part.tree >= trees)
      throw tsah::ConfigError(name + " takes tree " + std::to_string(part.tree) + " of a set of " + std::to_string(trees));
    if (part.keyTimes.size() != part.keyPositions.size())
      throw tsah::ConfigError(name + " has " + std::to_string(part.keyTimes.size()) + " key times and " +
                              std::to_string(part.keyPositions.size()) + " position sets");
    if (part.keyTimes.size() < 2) throw tsah::ConfigError(name + " has fewer than two keys");
    if (p > 0) {
      if (part.tree <= parts[p - 1].tree)
        throw tsah::ConfigError(name + " takes tree " + std::to_string(part.tree) + " after tree " +
                                std::to_string(parts[p - 1].tree) + " (each tree once, in the set's order)");
      if (!(part.keyTimes.front() == times.back()))
        throw tsah::ConfigError(name + " starts at " + std::to_string(part.keyTimes.front()) +
                                ", not where part " + std::to_string(p - 1) + " ends");
    }
    times.insert(times.end(), part.keyTimes.begin() + (p > 0 ? 1 : 0), part.keyTimes.end());
  }
  motion::checkKeyTimes(times, times.size(), "runtime: ");
  return times;
}

}  // namespace

void CpuRuntime::updateShutter(std::span<const ShutterPart> parts) {
  const std::vector<float> allTimes = checkedPartTimes(parts, treeCount());
  if (allTimes.size() == 1) {
    switchTree(parts[0].tree);
    update(parts[0].keyPositions[0]);
    return;
  }
  const std::size_t floats = std::size_t(vertexCount_) * 3;
  std::size_t bytes = 0;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    const ShutterPart& part = parts[p];
    for (std::size_t k = 0; k < part.keyPositions.size(); ++k)
      if (part.keyPositions[k].size() != floats)
        throw tsah::DataError("runtime: key " + std::to_string(k) + (parts.size() > 1 ? " of part " + std::to_string(p) : "") +
                              " has " + std::to_string(part.keyPositions[k].size()) + " coordinates, expected " +
                              std::to_string(floats));
    // Per key of the part's tree (a set keeps each tree's own copies): its node set and (wide)
    // vertex packets.
    const uint32_t t = part.tree;
    const WideTree<4>* w4 = setWide4_.empty() ? wide4_.get() : setWide4_[t].get();
    const WideTree<8>* w8 = setWide8_.empty() ? wide8_.get() : setWide8_[t].get();
    std::size_t keyBytes = floats * sizeof(float) + sizeof(Aabb);
    if (w4)
      keyBytes += w4->nodes().size() * sizeof(WideSoaNode<4>) + w4->packetCount() * sizeof(KeyVertexPacket<4>);
    else if (w8)
      keyBytes += w8->nodes().size() * sizeof(WideSoaNode<8>) + w8->packetCount() * sizeof(KeyVertexPacket<8>);
    else
      keyBytes += (setTrees_.empty() ? tree_ : setTrees_[t]).interiorCount * sizeof(GpuBvhNode);
    bytes += part.keyTimes.size() * keyBytes;
  }
  checkFitsInMemory(bytes, "runtime", "a shutter of " + std::to_string(allTimes.size()) + " keys");
  // A key whose positions equal, bit for bit, a key of the previous shutter's part of the same tree
  // keeps that key's refit (consecutive frames whose shutters meet share the key between them): the
  // refit is a function of the tree and the positions, and a part's tree does not change.
  // With Config::movingVertices, once positions were read in full, the keys' static vertices are
  // those positions: only the moving ones are read, compared and checked.
  const bool readMovingOnly = movingVertices_.has_value() && staticPositionsRead_;
  const auto sameKey = [&](std::span<const float> given, const BlurredPart& old, std::size_t key) {
    const std::span<const float> kept = std::span<const float>(old.keyPositions).subspan(key * floats, floats);
    if (!readMovingOnly) return sameBits(given, kept);
    for (uint32_t v : *movingVertices_)
      if (std::memcmp(given.data() + 3 * std::size_t(v), kept.data() + 3 * std::size_t(v), 3 * sizeof(float)) != 0)
        return false;
    return true;
  };
  std::vector<BlurredPart> old = std::move(parts_);
  parts_.clear();  // restored below when a check fails
  std::vector<std::size_t> oldOf(parts.size(), old.size());  // the previous part of the same tree
  std::vector<std::vector<std::size_t>> reused(parts.size());
  try {
    for (std::size_t p = 0; p < parts.size(); ++p) {
      for (std::size_t j = 0; j < old.size(); ++j)
        if (old[j].tree == parts[p].tree) oldOf[p] = j;
      const std::size_t oldKeys = oldOf[p] < old.size() ? old[oldOf[p]].keyTimes.size() : 0;
      reused[p].assign(parts[p].keyTimes.size(), oldKeys);
      for (std::size_t k = 0; k < parts[p].keyTimes.size(); ++k)
        for (std::size_t j = 0; j < oldKeys; ++j)
          if (sameKey(parts[p].keyPositions[k], old[oldOf[p]], j)) {
            reused[p][k] = j;
            break;
          }
      // Every key to refit is checked first, so that an error leaves the runtime as it was.
      for (std::size_t k = 0; k < parts[p].keyTimes.size(); ++k)
        if (reused[p][k] == oldKeys)
          readMovingOnly ? checkMovingPositions(parts[p].keyPositions[k]) : checkPositions(parts[p].keyPositions[k]);
    }
  } catch (...) {
    parts_ = std::move(old);
    throw;
  }
  BlurredPart none;
  std::vector<BlurredPart> next;
  next.reserve(parts.size());
  keysRefitted_ = 0;
  keysRefittedMovingOnly_ = 0;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    switchTree(parts[p].tree);
    BlurredPart& from = oldOf[p] < old.size() ? old[oldOf[p]] : none;
    next.push_back(makePart(parts[p].tree, parts[p].keyTimes, parts[p].keyPositions, reused[p], readMovingOnly, from));
  }
  // A dropped part's position buffer is the next frame's (a fresh one would be zeroed and faulted in).
  for (BlurredPart& dropped : old)
    if (dropped.keyPositions.capacity() > spareKeyPositions_.capacity()) spareKeyPositions_ = std::move(dropped.keyPositions);
  parts_ = std::move(next);
  // The runtime's positions are the last key's (the renderer's smooth normals read them).
  const BlurredPart& last = parts_.back();
  if (const std::span<const float> key = std::span<const float>(last.keyPositions).subspan(last.keyPositions.size() - floats);
      !sameBits(positions_, key))
    positions_.assign(key.begin(), key.end());
  staticPositionsRead_ = true;
}

CpuRuntime::BlurredPart CpuRuntime::makePart(uint32_t tree, std::span<const float> keyTimes,
                                             std::span<const std::span<const float>> keyPositions,
                                             const std::vector<std::size_t>& reused, bool readMovingOnly,
                                             BlurredPart& old) {
  const std::size_t keys = keyTimes.size(), floats = std::size_t(vertexCount_) * 3;
  const std::size_t oldKeys = old.keyTimes.size();
  BlurredPart part;
  part.tree = tree;
  part.keyTimes.assign(keyTimes.begin(), keyTimes.end());
  part.keyNodes.resize(wide4_ || wide8_ ? 0 : keys * tree_.interiorCount);
  part.keyRootBoxes.resize(keys);
  part.keyPositions = std::move(spareKeyPositions_);
  spareKeyPositions_.clear();
  part.keyPositions.resize(keys * floats);
  if (wide4_) part.wide4 = passOnWideKeys(old.wide4, reused);
  if (wide8_) part.wide8 = passOnWideKeys(old.wide8, reused);
  for (std::size_t k = 0; k < keys; ++k) {
    if (reused[k] < oldKeys) {  // key `from` of the old part: its positions, root box and binary nodes
      const std::size_t from = reused[k];
      const auto copy = [&](const auto& sets, auto& into) {
        if (sets.empty()) return;
        const std::size_t size = sets.size() / oldKeys;
        std::copy_n(sets.begin() + std::ptrdiff_t(from * size), size, into.begin() + std::ptrdiff_t(k * size));
      };
      copy(old.keyNodes, part.keyNodes);
      copy(old.keyPositions, part.keyPositions);
      part.keyRootBoxes[k] = old.keyRootBoxes[from];
    } else {
      refitShutterKey(keyPositions[k], readMovingOnly, part, k);
      ++keysRefitted_;
    }
  }
  // The wide view's tree fields (root, packets' slots, triangle ids) for the segments, also when no
  // update() came before.
  if (wide4_) {
    view4_ = wide4_->view(indices_.data(), positions_.data());
    setSegments(view4_, part, &BlurredPart::wide4, &BlurredPart::segments4);
  }
  if (wide8_) {
    view8_ = wide8_->view(indices_.data(), positions_.data());
    setSegments(view8_, part, &BlurredPart::wide8, &BlurredPart::segments8);
  }
  // The key positions, times and triangles in every layout (the renderer's blurred surfaces read
  // them); the binary key nodes in bvh2 only. The tree's fields come from the set's copy, which
  // stays when a later part switches the runtime's tree.
  const bool wide = wide4_ || wide8_;
  const FlatBvh& topology = setTrees_.empty() ? tree_ : setTrees_[tree];
  MotionBvhView& v = part.view;
  v.keyNodes = wide ? nullptr : part.keyNodes.data();
  v.keyRootBoxes = part.keyRootBoxes.data();
  v.keyPositions = part.keyPositions.data();
  v.keyTimes = part.keyTimes.data();
  v.keyCount = uint32_t(keys);
  v.nodeCount = wide ? 0u : topology.interiorCount;
  v.vertexCount = vertexCount_;
  v.triIndex = topology.triIndex.data();
  v.indices = indices_.data();
  v.rootRef = topology.rootRef;
  v.rootCount = topology.rootCount;
  return part;
}

Hit CpuRuntime::closestHit(const Ray& ray, float time) const {
  if (!blurred()) return closestHit(ray);
  const BlurredPart& part = parts_[partAt(time)];
  if (wide8_)
    return traceSegment(part, part.segments8, time, [&](const auto& v, const auto& m) { return kernels_->closestMotion8(v, m, ray); });
  if (wide4_)
    return traceSegment(part, part.segments4, time, [&](const auto& v, const auto& m) { return kernels_->closestMotion4(v, m, ray); });
  return tsah::closestHit(part.view, ray, time);
}

bool CpuRuntime::anyHit(const Ray& ray, float time, AnyHitOrder order) const {
  if (!blurred()) return anyHit(ray, order);
  const BlurredPart& part = parts_[partAt(time)];
  if (wide8_)
    return traceSegment(part, part.segments8, time, [&](const auto& v, const auto& m) { return kernels_->anyMotion8(v, m, ray, order); });
  if (wide4_)
    return traceSegment(part, part.segments4, time, [&](const auto& v, const auto& m) { return kernels_->anyMotion4(v, m, ray, order); });
  return tsah::anyHit(part.view, ray, time);
}

}  // namespace tsah
