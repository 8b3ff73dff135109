// The GPU's closest-point and box-overlap queries (gpu_queries.hpp): proximity.hpp's traversal
// over the runtime's refitted binary tree, one thread per query.
#include <algorithm>

#include "cwbvh_kernels.hpp"
#include "launch.hpp"
#include "runtime_impl.hpp"
#include "tsah/base/error.hpp"
#include "tsah/layout/proximity.hpp"
#include "tsah_cuda/gpu_queries.hpp"

namespace tsah::cuda {

// The runtime's state for the queries (a friend of GpuRuntime).
struct QueryAccess {
  static GpuRuntime::Impl& of(GpuRuntime& runtime) { return *runtime.impl_; }
};

namespace {

constexpr unsigned kBlock = 128;

__device__ tsah::detail::BinaryQueryTree queryTree(const detail::TraceScene& scene) {
  BvhView view;
  view.nodes = scene.nodes;
  view.triIndex = scene.triIndex;
  view.indices = scene.indices;
  view.positions = scene.positions;
  return tsah::detail::BinaryQueryTree{view};
}

__global__ void __launch_bounds__(kBlock) closestPointKernel(detail::TraceScene scene, const Vec3* __restrict__ points,
                                                             const float* __restrict__ radii, bool oneRadius,
                                                             uint32_t count, PointHit* __restrict__ hits) {
  const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  const detail::RootInfo root = *scene.root;
  hits[i] = closestPoint(queryTree(scene), root.box, root.ref, root.count, points[i], radii[oneRadius ? 0 : i]);
}

// offsets == nullptr: writes each box's count to counts[q]; else writes its ids from offsets[q].
__global__ void __launch_bounds__(kBlock) overlapKernel(detail::TraceScene scene, const Aabb* __restrict__ boxes,
                                                        uint32_t count, uint32_t* __restrict__ counts,
                                                        const uint64_t* __restrict__ offsets,
                                                        uint32_t* __restrict__ ids) {
  const uint32_t q = blockIdx.x * blockDim.x + threadIdx.x;
  if (q >= count) return;
  const detail::RootInfo root = *scene.root;
  const tsah::detail::BinaryQueryTree tree = queryTree(scene);
  if (offsets == nullptr) {
    counts[q] = overlappingTriangles(tree, root.box, root.ref, root.count, boxes[q], [](uint32_t) {});
  } else {
    uint32_t* out = ids + offsets[q];
    uint32_t n = 0;
    overlappingTriangles(tree, root.box, root.ref, root.count, boxes[q], [&](uint32_t tri) { out[n++] = tri; });
  }
}

// The traced scene, when the queries can read it: the binary tree of this frame.
detail::TraceScene queryScene(GpuRuntime::Impl& m, std::size_t queries) {
  m.requireTraceable();
  const detail::TraceScene scene = m.scene();
  if (scene.cwbvhNodes)
    throw tsah::ConfigError("GPU queries: layout cwbvh does not refit the binary tree (use layout bvh2)");
  if (queries > 0xffffffffu) throw tsah::ConfigError("GPU queries: too many queries in one call");
  return scene;
}

}  // namespace

std::vector<PointHit> closestPoints(GpuRuntime& runtime, std::span<const Vec3> points, std::span<const float> radii,
                                    RayPassStats* stats) {
  checkPointQueries(points, radii);
  GpuRuntime::Impl& m = QueryAccess::of(runtime);
  const detail::TraceScene scene = queryScene(m, points.size());
  if (stats) *stats = {};
  if (points.empty()) return {};
  const auto count = static_cast<uint32_t>(points.size());
  DeviceBuffer<Vec3> devicePoints(points, m.stream);
  DeviceBuffer<float> deviceRadii(radii, m.stream);
  DeviceBuffer<PointHit> hits(count);
  m.events.record(0, m.stream);
  closestPointKernel<<<detail::gridFor(count, kBlock), kBlock, 0, m.stream>>>(
      scene, devicePoints.data(), deviceRadii.data(), radii.size() == 1, count, hits.data());
  CUDA_CHECK_LAUNCH("closestPointKernel");
  m.events.record(1, m.stream);
  std::vector<PointHit> out = hits.download(m.stream);
  if (stats) *stats = {count, m.events.ms(0, 1)};
  return out;
}

BoxOverlaps overlappingTriangles(GpuRuntime& runtime, std::span<const Aabb> boxes, RayPassStats* stats) {
  checkBoxQueries(boxes);
  GpuRuntime::Impl& m = QueryAccess::of(runtime);
  const detail::TraceScene scene = queryScene(m, boxes.size());
  if (stats) *stats = {};
  BoxOverlaps out;
  out.offsets.assign(boxes.size() + 1, 0);
  if (boxes.empty()) return out;
  const auto count = static_cast<uint32_t>(boxes.size());
  const unsigned grid = detail::gridFor(count, kBlock);
  DeviceBuffer<Aabb> deviceBoxes(boxes, m.stream);
  DeviceBuffer<uint32_t> counts(count);
  m.events.record(0, m.stream);
  overlapKernel<<<grid, kBlock, 0, m.stream>>>(scene, deviceBoxes.data(), count, counts.data(), nullptr, nullptr);
  CUDA_CHECK_LAUNCH("overlapKernel<count>");
  m.events.record(1, m.stream);
  // The prefix sum of the counts on the host (64-bit: the total may pass 2^32).
  const std::vector<uint32_t> hostCounts = counts.download(m.stream);
  const double countMs = m.events.ms(0, 1);
  for (uint32_t q = 0; q < count; ++q) out.offsets[q + 1] = out.offsets[q] + hostCounts[q];
  out.triangles.resize(out.offsets.back());
  if (!out.triangles.empty()) {
    DeviceBuffer<uint64_t> offsets(out.offsets, m.stream);
    DeviceBuffer<uint32_t> ids(out.triangles.size());
    m.events.record(0, m.stream);
    overlapKernel<<<grid, kBlock, 0, m.stream>>>(scene, deviceBoxes.data(), count, nullptr, offsets.data(), ids.data());
    CUDA_CHECK_LAUNCH("overlapKernel<fill>");
    m.events.record(1, m.stream);
    out.triangles = ids.download(m.stream);
    for (uint32_t q = 0; q < count; ++q)
      std::sort(out.triangles.begin() + out.offsets[q], out.triangles.begin() + out.offsets[q + 1]);
  }
  if (stats) *stats = {count, countMs + (out.triangles.empty() ? 0.0 : m.events.ms(0, 1))};
  return out;
}

}  // namespace tsah::cuda
