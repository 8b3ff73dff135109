// Closest points and box overlap as methods of tsah.CpuRuntime and tsah.GpuRuntime (the classes
// are bound in runtime.cpp; the queries are tsah/runtime/queries.hpp and tsah_cuda/gpu_queries.hpp).
#include <algorithm>
#include <cstddef>
#include <cstring>
#include <limits>

#include "bindings.hpp"
#include "tsah/runtime/queries.hpp"
#if defined(TSAH_HAVE_CUDA)
#include "tsah_cuda/gpu_queries.hpp"
#endif

namespace tsah::python {

namespace {

using namespace pybind11::literals;

// points (N, 3) as Vec3; radius a number or an array (N,) (the library checks the values).
std::vector<Vec3> pointsOf(py::handle points) {
  static_assert(sizeof(Vec3) == 3 * sizeof(float));
  const auto a = checkedArray<float>(points, "points", Kind::Number, {-1, 3});
  std::vector<Vec3> out(std::size_t(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(Vec3));
  return out;
}

std::vector<float> radiiOf(py::handle radius, std::size_t points) {
  if (py::isinstance<py::float_>(radius) || py::isinstance<py::int_>(radius)) return {radius.cast<float>()};
  const auto a = checkedArray<float>(radius, "radius", Kind::Number, {py::ssize_t(points)});
  return {a.data(), a.data() + points};
}

std::vector<Aabb> boxesOf(py::handle lo, py::handle hi) {
  const auto l = checkedArray<float>(lo, "lo", Kind::Number, {-1, 3});
  const auto h = checkedArray<float>(hi, "hi", Kind::Number, {l.shape(0), 3});
  std::vector<Aabb> out(std::size_t(l.shape(0)));
  for (std::size_t i = 0; i < out.size(); ++i) {
    out[i].lo = {l.data()[3 * i], l.data()[3 * i + 1], l.data()[3 * i + 2]};
    out[i].hi = {h.data()[3 * i], h.data()[3 * i + 1], h.data()[3 * i + 2]};
  }
  return out;
}

// PointHit as a numpy record: distance, triangle (-1: none within the radius: the bits of
// tsah::kNoHit), u, v, point (3 float32).
py::array pointHitArray(const std::vector<PointHit>& hits) {
  static_assert(sizeof(PointHit) == 28 && offsetof(PointHit, tri) == 4 && offsetof(PointHit, point) == 16);
  py::dict spec("names"_a = py::make_tuple("distance", "triangle", "u", "v", "point"),
                "formats"_a = py::make_tuple("<f4", "<i4", "<f4", "<f4", "(3,)<f4"),
                "offsets"_a = py::make_tuple(0, 4, 8, 12, 16), "itemsize"_a = 28);
  py::array out(py::dtype::from_args(spec), std::vector<py::ssize_t>{py::ssize_t(hits.size())});
  if (!hits.empty()) std::memcpy(out.mutable_data(), hits.data(), hits.size() * sizeof(PointHit));
  return out;
}

py::tuple overlapArrays(const BoxOverlaps& found) {
  py::array_t<int64_t> offsets(py::ssize_t(found.offsets.size()));
  std::copy(found.offsets.begin(), found.offsets.end(), offsets.mutable_data());
  py::array_t<int32_t> ids(py::ssize_t(found.triangles.size()));
  std::copy(found.triangles.begin(), found.triangles.end(), ids.mutable_data());
  return py::make_tuple(offsets, ids);
}

constexpr const char* kClosestDoc = R"doc(
For each point, the closest point on the current frame's triangles within radius (distance <=
radius). points: float array (N, 3); radius: a number or an array (N,), each >= 0 (inf: no limit).
Returns a numpy record array (N,) with fields distance (float32, inf when nothing lies within the
radius), triangle (int32, -1 then), u, v (float32: point = (1-u-v)*v0 + u*v1 + v*v2) and point
(float32 (3,)). At equal distance the lowest triangle id wins.
)doc";
constexpr const char* kOverlapDoc = R"doc(
For each query box (lo[i], hi[i], float arrays (N, 3), lo <= hi), the triangles whose box in the
current frame overlaps it (touching counts). Returns (offsets, ids): offsets int64 (N + 1,), ids
int32; box i's triangles are ids[offsets[i]:offsets[i + 1]], ascending.
)doc";

// Adds fn to the bound class `name` as a method.
template <class Fn, class... Extra>
void addMethod(py::module_& m, const char* cls, const char* name, Fn&& fn, const Extra&... extra) {
  py::object type = m.attr(cls);
  type.attr(name) = py::cpp_function(std::forward<Fn>(fn), py::name(name), py::is_method(type),
                                     py::sibling(py::getattr(type, name, py::none())), extra...);
}

}  // namespace

void bindQueries(py::module_& m) {
  const float inf = std::numeric_limits<float>::infinity();
  addMethod(
      m, "CpuRuntime", "closest_points",
      [](py::handle self, py::handle points, py::handle radius) {
        const CpuRuntime& runtime = cpuRuntimeOf(self);
        const std::vector<Vec3> p = pointsOf(points);
        const std::vector<float> r = radiiOf(radius, p.size());
        std::vector<PointHit> hits;
        {
          py::gil_scoped_release release;
          hits = closestPoints(runtime, p, r);
        }
        return pointHitArray(hits);
      },
      "points"_a, "radius"_a = inf, kClosestDoc);
  addMethod(
      m, "CpuRuntime", "overlapping_triangles",
      [](py::handle self, py::handle lo, py::handle hi) {
        const CpuRuntime& runtime = cpuRuntimeOf(self);
        const std::vector<Aabb> boxes = boxesOf(lo, hi);
        BoxOverlaps found;
        {
          py::gil_scoped_release release;
          found = overlappingTriangles(runtime, boxes);
        }
        return overlapArrays(found);
      },
      "lo"_a, "hi"_a, kOverlapDoc);
#if defined(TSAH_HAVE_CUDA)
  addMethod(
      m, "GpuRuntime", "closest_points",
      [](py::handle self, py::handle points, py::handle radius) {
        cuda::GpuRuntime& runtime = gpuRuntimeOf(self);
        const std::vector<Vec3> p = pointsOf(points);
        const std::vector<float> r = radiiOf(radius, p.size());
        std::vector<PointHit> hits;
        {
          py::gil_scoped_release release;
          hits = cuda::closestPoints(runtime, p, r);
        }
        return pointHitArray(hits);
      },
      "points"_a, "radius"_a = inf, kClosestDoc);
  addMethod(
      m, "GpuRuntime", "overlapping_triangles",
      [](py::handle self, py::handle lo, py::handle hi) {
        cuda::GpuRuntime& runtime = gpuRuntimeOf(self);
        const std::vector<Aabb> boxes = boxesOf(lo, hi);
        BoxOverlaps found;
        {
          py::gil_scoped_release release;
          found = cuda::overlappingTriangles(runtime, boxes);
        }
        return overlapArrays(found);
      },
      "lo"_a, "hi"_a, kOverlapDoc);
#endif
}

}  // namespace tsah::python
