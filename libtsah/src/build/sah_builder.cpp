#include "tsah/build/sah_builder.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

bool finite(const Aabb& b) {
  return std::isfinite(b.lo.x) && std::isfinite(b.lo.y) && std::isfinite(b.lo.z) &&
         std::isfinite(b.hi.x) && std::isfinite(b.hi.y) && std::isfinite(b.hi.z);
}

// Distance of a split from the middle (times 2, to stay integral).
inline uint32_t balance(uint32_t split, uint32_t size) {
  return split * 2 > size ? split * 2 - size : size - split * 2;
}

struct Task {
  uint32_t node, begin, end;
};

}  // namespace

Bvh SweepSahBuilder::build(std::span<const Aabb> boxes) const {
  Bvh bvh;
  bvh.frameCount = 1;
  const std::size_t count = boxes.size();
  if (count == 0) return bvh;
  if (count >= std::size_t(std::numeric_limits<uint32_t>::max() / 2))
    throw tsah::DataError("SweepSahBuilder: too many primitives (" + std::to_string(count) + ")");
  const uint32_t n = static_cast<uint32_t>(count);

  std::vector<Vec3> centroid(n);
  for (uint32_t i = 0; i < n; ++i) {
    if (!finite(boxes[i]))
      throw tsah::DataError("SweepSahBuilder: primitive " + std::to_string(i) + " has a non-finite box");
    centroid[i] = boxes[i].center();
  }
  // One order per axis, sorted once; ties broken by id so the result never depends on the sort.
  std::array<std::vector<uint32_t>, 3> order;
  for (int axis = 0; axis < 3; ++axis) {
    order[axis].resize(n);
    std::iota(order[axis].begin(), order[axis].end(), 0u);
    std::sort(order[axis].begin(), order[axis].end(), [&](uint32_t a, uint32_t b) {
      const float ca = centroid[a][axis], cb = centroid[b][axis];
      return ca < cb || (ca == cb && a < b);
    });
  }

  bvh.nodes.reserve(2 * std::size_t(n) - 1);
  bvh.boxes.reserve(2 * std::size_t(n) - 1);
  bvh.nodes.emplace_back();
  bvh.boxes.emplace_back();
  bvh.root = 0;

  std::vector<float> rightArea(n);
  std::vector<uint8_t> goesLeft(n);
  std::vector<uint32_t> scratch(n);
  std::vector<Task> stack{{0, 0, n}};
  const double ct = config_.cost.ct, ci = config_.cost.ci;

  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    const uint32_t size = task.end - task.begin;
    Aabb box;
    for (uint32_t i = task.begin; i < task.end; ++i) box.extend(boxes[order[0][i]]);
    bvh.boxes[task.node] = box;

    if (size == 1) {
      bvh.nodes[task.node].primBegin = task.begin;
      bvh.nodes[task.node].primCount = 1;
      continue;
    }

    // Sweep every axis: right-to-left suffix areas, then left-to-right prefix boxes.
    double bestCost = std::numeric_limits<double>::infinity();
    int bestAxis = 0;
    uint32_t bestSplit = 1;  // number of primitives on the left
    for (int axis = 0; axis < 3; ++axis) {
      const uint32_t* ids = order[axis].data() + task.begin;
      Aabb right;
      for (uint32_t i = size - 1; i >= 1; --i) {
        right.extend(boxes[ids[i]]);
        rightArea[i] = right.area();
      }
      Aabb left;
      for (uint32_t i = 1; i < size; ++i) {
        left.extend(boxes[ids[i - 1]]);
        const double cost = double(left.area()) * i + double(rightArea[i]) * (size - i);
        // Equal costs (e.g. identical boxes): prefer the more balanced split, so duplicates do not
        // degenerate into a deep chain.
        const bool better = cost < bestCost ||
                            (cost == bestCost && balance(i, size) < balance(bestSplit, size));
        if (better) {
          bestCost = cost;
          bestAxis = axis;
          bestSplit = i;
        }
      }
    }

    if (size <= config_.maxLeafSize) {
      const double area = box.area();
      if (ci * size * area <= ct * area + ci * bestCost) {
        bvh.nodes[task.node].primBegin = task.begin;
        bvh.nodes[task.node].primCount = size;
        continue;
      }
    }

    // Keep the other two orders partitioned the same way, stably.
    const uint32_t* chosen = order[bestAxis].data() + task.begin;
    for (uint32_t i = 0; i < size; ++i) goesLeft[chosen[i]] = i < bestSplit;
    for (int axis = 0; axis < 3; ++axis) {
      if (axis == bestAxis) continue;
      uint32_t* ids = order[axis].data() + task.begin;
      uint32_t l = 0, r = bestSplit;
      for (uint32_t i = 0; i < size; ++i) scratch[goesLeft[ids[i]] ? l++ : r++] = ids[i];
      std::copy(scratch.begin(), scratch.begin() + size, ids);
    }

    const auto left = static_cast<uint32_t>(bvh.nodes.size());
    const uint32_t right = left + 1;
    bvh.nodes[task.node].left = left;
    bvh.nodes[task.node].right = right;
    bvh.nodes.emplace_back().parent = task.node;
    bvh.nodes.emplace_back().parent = task.node;
    bvh.boxes.emplace_back();
    bvh.boxes.emplace_back();
    const uint32_t mid = task.begin + bestSplit;
    stack.push_back({right, mid, task.end});
    stack.push_back({left, task.begin, mid});
  }
  bvh.primIds = std::move(order[0]);
  limitDepth(bvh);  // SAH splits of boxes spread over many scales can chain
  return bvh;
}

}  // namespace tsah
