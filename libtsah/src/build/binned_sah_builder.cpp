#include "tsah/build/binned_sah_builder.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

constexpr uint32_t kMaxBins = 256;

struct Bin {
  Aabb box;
  uint32_t count = 0;
};

// Box and centroid box of a primitive range.
struct RangeBounds {
  Aabb box, centroids;
  void add(const RangeBounds& o) {
    box.extend(o.box);
    centroids.extend(o.centroids);
  }
};

struct Split {
  int axis = -1;
  uint32_t bin = 0;  // primitives in bins [0, bin] go left
  float cost = 0.0f;
};

class Build {
 public:
  Build(const BinnedSahBuilder::Config& config, std::span<const Aabb> boxes) : cfg_(config), boxes_(boxes) {
    centers_.resize(boxes.size());
    ids_.resize(boxes.size());
    tbb::parallel_for(std::size_t(0), boxes.size(), std::size_t(4096), [&](std::size_t i) {
      const std::size_t end = std::min(boxes.size(), i + 4096);
      for (std::size_t p = i; p < end; ++p) {
        centers_[p] = boxes[p].center();
        ids_[p] = static_cast<uint32_t>(p);
      }
    });
  }

  Bvh run() {
    Bvh bvh;
    bvh.frameCount = 1;
    const auto n = static_cast<uint32_t>(boxes_.size());
    if (n == 0) return bvh;
    bvh.nodes.reserve(2 * std::size_t(n) - 1);
    bvh.boxes.reserve(2 * std::size_t(n) - 1);

    // Top of the tree: nodes above parallelThreshold, built here with parallel bounds, binning and
    // (stable) partitioning.
    struct Task {
      uint32_t slot, begin, end;
      RangeBounds bounds;
    };
    std::vector<Task> tasks;
    struct Item {
      uint32_t slot, begin, end;
    };
    bvh.nodes.push_back({});
    bvh.boxes.push_back({});
    std::vector<Item> stack{{0, 0, n}};
    while (!stack.empty()) {
      const Item item = stack.back();
      stack.pop_back();
      const RangeBounds rb = bounds(item.begin, item.end, true);
      if (item.end - item.begin <= cfg_.parallelThreshold) {
        tasks.push_back({item.slot, item.begin, item.end, rb});
        continue;
      }
      bvh.boxes[item.slot] = rb.box;
      uint32_t mid;
      if (!splitRange(item.begin, item.end, rb, true, mid)) {  // cannot happen above maxLeafSize
        makeLeaf(bvh.nodes[item.slot], item.begin, item.end);
        continue;
      }
      const auto left = static_cast<uint32_t>(bvh.nodes.size());
      bvh.nodes.push_back({});
      bvh.nodes.push_back({});
      bvh.boxes.push_back({});
      bvh.boxes.push_back({});
      bvh.nodes[item.slot].left = left;
      bvh.nodes[item.slot].right = left + 1;
      bvh.nodes[left].parent = bvh.nodes[left + 1].parent = item.slot;
      stack.push_back({left + 1, mid, item.end});
      stack.push_back({left, item.begin, mid});
    }

    std::vector<uint32_t>().swap(scratch_);

    // Subtrees: one task each, into private arrays, then copied in task order: task t's nodes but
    // its root go to [first[t], first[t + 1]), so the copies run concurrently.
    struct Local {
      std::vector<BvhNode> nodes;
      std::vector<Aabb> boxes;
    };
    std::vector<Local> locals(tasks.size());
    tbb::parallel_for(std::size_t(0), tasks.size(), [&](std::size_t t) {
      buildSerial(tasks[t].begin, tasks[t].end, tasks[t].bounds, locals[t].nodes, locals[t].boxes);
    });
    std::vector<uint32_t> first(tasks.size() + 1);
    first[0] = static_cast<uint32_t>(bvh.nodes.size());
    for (std::size_t t = 0; t < tasks.size(); ++t) first[t + 1] = first[t] + uint32_t(locals[t].nodes.size() - 1);
    bvh.nodes.resize(first.back());
    bvh.boxes.resize(first.back());
    tbb::parallel_for(std::size_t(0), tasks.size(), [&](std::size_t t) {
      Local& local = locals[t];
      const uint32_t slot = tasks[t].slot, base = first[t];
      auto map = [&](uint32_t k) { return k == 0 ? slot : base + k - 1; };
      const uint32_t rootParent = bvh.nodes[slot].parent;
      for (std::size_t k = 0; k < local.nodes.size(); ++k) {
        BvhNode node = local.nodes[k];
        node.parent = k == 0 ? rootParent : map(node.parent);
        if (!node.isLeaf()) {
          node.left = map(node.left);
          node.right = map(node.right);
        }
        bvh.nodes[map(uint32_t(k))] = node;
        bvh.boxes[map(uint32_t(k))] = local.boxes[k];
      }
      local = Local{};
    });
    bvh.primIds = std::move(ids_);
    return bvh;
  }

 private:
  static void makeLeaf(BvhNode& node, uint32_t begin, uint32_t end) {
    node.primBegin = begin;
    node.primCount = end - begin;
    node.left = node.right = kInvalidIndex;
  }

  // Subtree over [begin, end) with local numbering: root 0, children adjacent.
  void buildSerial(uint32_t begin, uint32_t end, const RangeBounds& rootBounds, std::vector<BvhNode>& nodes,
                   std::vector<Aabb>& boxes) {
    struct Item {
      uint32_t slot, begin, end;
      RangeBounds bounds;
    };
    nodes.assign(1, BvhNode{});
    boxes.assign(1, rootBounds.box);
    std::vector<Item> stack{{0, begin, end, rootBounds}};
    while (!stack.empty()) {
      const Item item = stack.back();
      stack.pop_back();
      boxes[item.slot] = item.bounds.box;
      uint32_t mid;
      if (!splitRange(item.begin, item.end, item.bounds, false, mid)) {
        makeLeaf(nodes[item.slot], item.begin, item.end);
        continue;
      }
      const auto left = static_cast<uint32_t>(nodes.size());
      nodes.resize(nodes.size() + 2);
      boxes.resize(boxes.size() + 2);
      nodes[item.slot].left = left;
      nodes[item.slot].right = left + 1;
      nodes[left].parent = nodes[left + 1].parent = item.slot;
      stack.push_back({left + 1, mid, item.end, bounds(mid, item.end, false)});
      stack.push_back({left, item.begin, mid, bounds(item.begin, mid, false)});
    }
  }

  // Chunks for the parallel passes over large ranges, merged in a fixed order (deterministic).
  static constexpr uint32_t kChunks = 64;

  RangeBounds bounds(uint32_t begin, uint32_t end, bool parallel) const {
    auto range = [&](uint32_t b, uint32_t e) {
      RangeBounds r;
      for (uint32_t i = b; i < e; ++i) {
        r.box.extend(boxes_[ids_[i]]);
        r.centroids.extend(centers_[ids_[i]]);
      }
      return r;
    };
    if (!parallel || end - begin < 2 * cfg_.parallelThreshold) return range(begin, end);
    std::array<RangeBounds, kChunks> parts;
    const uint32_t n = end - begin;
    tbb::parallel_for(uint32_t(0), kChunks, [&](uint32_t c) {
      parts[c] = range(begin + uint32_t(uint64_t(n) * c / kChunks), begin + uint32_t(uint64_t(n) * (c + 1) / kChunks));
    });
    RangeBounds r;
    for (const auto& p : parts) r.add(p);
    return r;
  }

  // Partitions ids_[begin, end) stably in kChunks chunks on the arena's threads: the ids that go
  // left first, each side in its old order (the same result for any thread count). Returns the
  // number that go left.
  template <typename GoesLeft>
  uint32_t stablePartition(uint32_t begin, uint32_t end, const GoesLeft& goesLeft) {
    const uint32_t n = end - begin;
    auto chunkBegin = [&](uint32_t c) { return begin + uint32_t(uint64_t(n) * c / kChunks); };
    std::array<uint32_t, kChunks + 1> leftBefore{};
    std::array<uint32_t, kChunks> leftIn{};
    tbb::parallel_for(uint32_t(0), kChunks, [&](uint32_t c) {
      uint32_t left = 0;
      for (uint32_t i = chunkBegin(c); i < chunkBegin(c + 1); ++i) left += goesLeft(ids_[i]) ? 1 : 0;
      leftIn[c] = left;
    });
    for (uint32_t c = 0; c < kChunks; ++c) leftBefore[c + 1] = leftBefore[c] + leftIn[c];
    const uint32_t leftTotal = leftBefore[kChunks];
    if (scratch_.size() < ids_.size()) scratch_.resize(ids_.size());
    tbb::parallel_for(uint32_t(0), kChunks, [&](uint32_t c) {
      uint32_t l = begin + leftBefore[c];
      uint32_t r = begin + leftTotal + (chunkBegin(c) - begin - leftBefore[c]);
      for (uint32_t i = chunkBegin(c); i < chunkBegin(c + 1); ++i) {
        const uint32_t p = ids_[i];
        scratch_[goesLeft(p) ? l++ : r++] = p;
      }
    });
    tbb::parallel_for(uint32_t(0), kChunks, [&](uint32_t c) {
      std::copy(scratch_.begin() + chunkBegin(c), scratch_.begin() + chunkBegin(c + 1), ids_.begin() + chunkBegin(c));
    });
    return leftTotal;
  }

  uint32_t binOf(float c, float lo, float scale) const {
    const float b = (c - lo) * scale;
    return b <= 0.0f ? 0u : std::min(cfg_.binCount - 1, static_cast<uint32_t>(b));
  }

  // Decides leaf or split for [begin, end); on a split partitions ids_ and sets mid.
  bool splitRange(uint32_t begin, uint32_t end, const RangeBounds& rb, bool parallel, uint32_t& mid) {
    const uint32_t count = end - begin;
    if (count == 1) return false;
    const float area = rb.box.area();
    const float leafCost = cfg_.cost.ci * float(count);

    Split best;
    best.cost = 3.4e38f;
    std::array<float, 3> lo{}, scale{};
    const uint32_t binCount = cfg_.binCount;
    std::vector<Bin> bins(3 * std::size_t(binCount));
    for (int axis = 0; axis < 3; ++axis) {
      const float extent = rb.centroids.hi[axis] - rb.centroids.lo[axis];
      lo[axis] = rb.centroids.lo[axis];
      scale[axis] = extent > 0.0f ? float(binCount) / extent * (1.0f - 1e-6f) : 0.0f;
    }
    auto binRange = [&](uint32_t b, uint32_t e, Bin* out) {
      for (uint32_t i = b; i < e; ++i) {
        const uint32_t p = ids_[i];
        for (int axis = 0; axis < 3; ++axis) {
          if (scale[axis] == 0.0f) continue;
          Bin& bin = out[axis * binCount + binOf(centers_[p][axis], lo[axis], scale[axis])];
          bin.box.extend(boxes_[p]);
          ++bin.count;
        }
      }
    };
    if (parallel && count >= 2 * cfg_.parallelThreshold) {
      std::vector<Bin> parts(kChunks * bins.size());
      tbb::parallel_for(uint32_t(0), kChunks, [&](uint32_t c) {
        binRange(begin + uint32_t(uint64_t(count) * c / kChunks), begin + uint32_t(uint64_t(count) * (c + 1) / kChunks),
                 parts.data() + c * bins.size());
      });
      for (uint32_t c = 0; c < kChunks; ++c)
        for (std::size_t b = 0; b < bins.size(); ++b) {
          bins[b].box.extend(parts[c * bins.size() + b].box);
          bins[b].count += parts[c * bins.size() + b].count;
        }
    } else {
      binRange(begin, end, bins.data());
    }

    std::vector<float> rightCost(binCount);
    for (int axis = 0; axis < 3; ++axis) {
      if (scale[axis] == 0.0f) continue;
      const Bin* axisBins = bins.data() + axis * binCount;
      Aabb acc;
      uint32_t n = 0;
      for (uint32_t b = binCount - 1; b > 0; --b) {  // rightCost[b]: bins [b, binCount)
        acc.extend(axisBins[b].box);
        n += axisBins[b].count;
        rightCost[b] = acc.area() * float(n);
      }
      acc = Aabb{};
      n = 0;
      for (uint32_t b = 0; b + 1 < binCount; ++b) {  // split after bin b
        acc.extend(axisBins[b].box);
        n += axisBins[b].count;
        if (n == 0 || n == count) continue;
        const float c = acc.area() * float(n) + rightCost[b + 1];
        if (c < best.cost) best = {axis, b, c};
      }
    }

    if (best.axis < 0) {
      // Every centroid in one place: no spatial split exists. Keep a leaf if allowed, else halve.
      if (count <= cfg_.maxLeafSize) return false;
      mid = begin + count / 2;
      return true;
    }
    const float splitCost = cfg_.cost.ct + cfg_.cost.ci * (area > 0.0f ? best.cost / area : float(count));
    if (count <= cfg_.maxLeafSize && leafCost <= splitCost) return false;
    const int axis = best.axis;
    const auto goesLeft = [&](uint32_t p) { return binOf(centers_[p][axis], lo[axis], scale[axis]) <= best.bin; };
    if (parallel && count >= 2 * cfg_.parallelThreshold) {
      mid = begin + stablePartition(begin, end, goesLeft);
    } else {
      const auto it = std::partition(ids_.begin() + begin, ids_.begin() + end, goesLeft);
      mid = static_cast<uint32_t>(it - ids_.begin());
    }
    if (mid == begin || mid == end) mid = begin + count / 2;  // unreachable: both sides counted non-empty
    return true;
  }

  const BinnedSahBuilder::Config& cfg_;
  std::span<const Aabb> boxes_;
  std::vector<Vec3> centers_;
  std::vector<uint32_t> ids_;
  std::vector<uint32_t> scratch_;  // the stable partition's copy of the ids
};

}  // namespace

Bvh BinnedSahBuilder::build(std::span<const Aabb> primBoxes) const {
  if (config_.binCount < 2 || config_.binCount > kMaxBins)
    throw tsah::ConfigError("binned SAH: bin count must be 2.." + std::to_string(kMaxBins));
  if (config_.maxLeafSize == 0) throw tsah::ConfigError("binned SAH: max leaf size must be at least 1");
  if (config_.parallelThreshold == 0) throw tsah::ConfigError("binned SAH: parallel threshold must be positive");
  if (primBoxes.size() >= std::size_t(kInvalidIndex) / 2)
    throw tsah::DataError("binned SAH: too many primitives for 32-bit node indices");
  for (const Aabb& b : primBoxes)
    if (!std::isfinite(b.lo.x) || !std::isfinite(b.lo.y) || !std::isfinite(b.lo.z) || !std::isfinite(b.hi.x) ||
        !std::isfinite(b.hi.y) || !std::isfinite(b.hi.z) || b.empty())
      throw tsah::DataError("binned SAH: a primitive box is empty or not finite");
  Build build(config_, primBoxes);
  Bvh bvh = build.run();
  limitDepth(bvh);  // SAH splits of boxes spread over many scales can chain
  return bvh;
}

}  // namespace tsah
