#include "tsah/runtime/queries.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "tsah/base/error.hpp"

namespace tsah {

namespace {

// Calls body(tree, rootBox, rootRef, rootCount) with the adapter of the layout the runtime traces.
template <class Body>
void withQueryTree(const CpuRuntime& runtime, Body&& body) {
  const uint32_t* indices = runtime.indices().data();
  const float* positions = runtime.positions().data();
  if (const WideTree<8>* wide8 = runtime.wide8()) {
    const detail::WideQueryTree<8> tree{wide8->view(indices, positions)};
    body(tree, tree.view.rootBox, tree.view.rootRef, tree.view.rootCount);
  } else if (const WideTree<4>* wide4 = runtime.wide4()) {
    const detail::WideQueryTree<4> tree{wide4->view(indices, positions)};
    body(tree, tree.view.rootBox, tree.view.rootRef, tree.view.rootCount);
  } else {
    const detail::BinaryQueryTree tree{runtime.view()};
    body(tree, tree.view.rootBox, tree.view.rootRef, tree.view.rootCount);
  }
}

constexpr std::size_t kGrain = 256;

}  // namespace

void checkPointQueries(std::span<const Vec3> points, std::span<const float> radii) {
  if (radii.size() != 1 && radii.size() != points.size())
    throw tsah::ConfigError("closest points: got " + std::to_string(radii.size()) + " radii for " +
                            std::to_string(points.size()) + " points (give one, or one per point)");
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!std::isfinite(points[i].x) || !std::isfinite(points[i].y) || !std::isfinite(points[i].z))
      throw tsah::ConfigError("closest points: point " + std::to_string(i) + " has a non-finite coordinate");
  for (std::size_t i = 0; i < radii.size(); ++i)
    if (!(radii[i] >= 0.0f))
      throw tsah::ConfigError("closest points: radius " + std::to_string(i) + " is negative or NaN");
}

void checkBoxQueries(std::span<const Aabb> boxes) {
  for (std::size_t i = 0; i < boxes.size(); ++i)
    for (int a = 0; a < 3; ++a)
      if (!(boxes[i].lo[a] <= boxes[i].hi[a]))
        throw tsah::ConfigError("box overlap: box " + std::to_string(i) + " has lo > hi or a NaN coordinate");
}

std::vector<PointHit> closestPoints(const CpuRuntime& runtime, std::span<const Vec3> points,
                                    std::span<const float> radii) {
  checkPointQueries(points, radii);
  std::vector<PointHit> hits(points.size());
  withQueryTree(runtime, [&](const auto& tree, const Aabb& rootBox, int32_t rootRef, uint32_t rootCount) {
    runtime.parallelFor(points.size(), kGrain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i)
        hits[i] = closestPoint(tree, rootBox, rootRef, rootCount, points[i], radii[radii.size() == 1 ? 0 : i]);
    });
  });
  return hits;
}

BoxOverlaps overlappingTriangles(const CpuRuntime& runtime, std::span<const Aabb> boxes) {
  checkBoxQueries(boxes);
  BoxOverlaps out;
  out.offsets.assign(boxes.size() + 1, 0);
  withQueryTree(runtime, [&](const auto& tree, const Aabb& rootBox, int32_t rootRef, uint32_t rootCount) {
    // Two passes, as on the GPU: count per query, then fill at the prefix sums.
    runtime.parallelFor(boxes.size(), kGrain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t q = begin; q < end; ++q)
        out.offsets[q + 1] = overlappingTriangles(tree, rootBox, rootRef, rootCount, boxes[q], [](uint32_t) {});
    });
    for (std::size_t q = 0; q < boxes.size(); ++q) out.offsets[q + 1] += out.offsets[q];
    out.triangles.resize(out.offsets.back());
    runtime.parallelFor(boxes.size(), kGrain, [&](std::size_t begin, std::size_t end) {
      for (std::size_t q = begin; q < end; ++q) {
        uint32_t* ids = out.triangles.data() + out.offsets[q];
        uint32_t n = 0;
        overlappingTriangles(tree, rootBox, rootRef, rootCount, boxes[q], [&](uint32_t tri) { ids[n++] = tri; });
        std::sort(ids, ids + n);
      }
    });
  });
  return out;
}

}  // namespace tsah
