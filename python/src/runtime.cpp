// Runtimes in the Python module: a tree refitted to a frame of its animation, tracing numpy arrays
// of rays on the CPU (tsah::CpuRuntime) or the GPU (tsah::cuda::GpuRuntime, when built).
#include <pybind11/stl.h>

#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <utility>

#include "anim/animation.hpp"
#include "bindings.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/wide_bvh.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/core/ray.hpp"
#if defined(TSAH_HAVE_CUDA)
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#endif

namespace tsah::python {

namespace {

using namespace pybind11::literals;

// origins (N, 3), directions (N, 3), tmin and tmax each a number or an array (N,).
std::vector<Ray> makeRays(py::handle origins, py::handle directions, py::handle tmin, py::handle tmax) {
  const auto org = checkedArray<float>(origins, "origins", Kind::Float, {-1, 3});
  const auto dir = checkedArray<float>(directions, "directions", Kind::Float, {org.shape(0), 3});
  const std::size_t n = std::size_t(org.shape(0));
  auto limits = [n](py::handle value, const char* name) {
    std::vector<float> out(n);
    if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)) {
      std::fill(out.begin(), out.end(), value.cast<float>());
    } else {
      const auto a = checkedArray<float>(value, name, Kind::Number, {py::ssize_t(n)});
      std::copy(a.data(), a.data() + n, out.begin());
    }
    return out;
  };
  const std::vector<float> lo = limits(tmin, "tmin"), hi = limits(tmax, "tmax");
  std::vector<Ray> rays(n);
  const float* o = org.data();
  const float* d = dir.data();
  for (std::size_t i = 0; i < n; ++i)
    rays[i] = {{o[3 * i], o[3 * i + 1], o[3 * i + 2]}, lo[i], {d[3 * i], d[3 * i + 1], d[3 * i + 2]}, hi[i]};
  checkRays(rays);
  return rays;
}

// tsah::Hit as a numpy record: t, u, v (float32) and triangle (int32, -1 when nothing was hit: the
// bits of tsah::kNoHit). A miss has t = inf (as in Embree and Warp) and u = v = 0.
py::array hitArray(std::vector<Hit> hits) {
  for (Hit& h : hits)
    if (!h.valid()) h = Hit{std::numeric_limits<float>::infinity(), 0.0f, 0.0f, h.tri};
  static_assert(sizeof(Hit) == 16 && offsetof(Hit, tri) == 12);
  py::dict spec("names"_a = py::make_tuple("t", "u", "v", "triangle"),
                "formats"_a = py::make_tuple("<f4", "<f4", "<f4", "<i4"), "offsets"_a = py::make_tuple(0, 4, 8, 12),
                "itemsize"_a = 16);
  py::array out(py::dtype::from_args(spec), std::vector<py::ssize_t>{py::ssize_t(hits.size())});
  if (!hits.empty()) std::memcpy(out.mutable_data(), hits.data(), hits.size() * sizeof(Hit));
  return out;
}

py::array_t<bool> boolArray(const std::vector<uint8_t>& flags) {
  py::array_t<bool> out(py::ssize_t(flags.size()));
  bool* p = out.mutable_data();
  for (std::size_t i = 0; i < flags.size(); ++i) p[i] = flags[i] != 0;
  return out;
}

// Vertex positions for a refit: NaN or infinite coordinates are refused as anim::Animation refuses
// them (their boxes would make every ray visit every node).
std::vector<float> checkedPositions(py::handle positions, uint32_t vertices) {
  const auto p = checkedArray<float>(positions, "positions", Kind::Float, {vertices, 3});
  for (py::ssize_t i = 0; i < p.size(); ++i)
    if (!std::isfinite(p.data()[i]))
      throw tsah::DataError("positions: vertex " + std::to_string(i / 3) + " has a NaN or infinite coordinate");
  return std::vector<float>(p.data(), p.data() + p.size());
}

}  // namespace

// The tree refitted to frames of its animation on the CPU.
class CpuTracer {
 public:
  // layout: "auto" (the widest this processor's SIMD kernels support, as `tsah trace`), "bvh2",
  // "bvh4" or "bvh8"; a wide layout is collapsed with the tree's own objective (its .tbvh header).
  CpuTracer(const Tree& tree, anim::Animation animation, unsigned threads, const std::string& layout)
      : animation_(std::move(animation)) {
    checkTreeMatchesAnimation(tree.file.info, "the tree", animation_, "'" + animation_.name() + "'");
    const Layout chosen = parse<Layout>(layout);
    if (chosen == Layout::Cwbvh) throw tsah::ConfigError("layout: cwbvh is a GPU layout (the CPU's are bvh2, bvh4, bvh8)");
    CpuRuntime::Config config;
    config.threads = threads;
    config.layout = chosen == Layout::Auto ? fastestLayout() : chosen;
    config.collapse = wideCollapseConfig(tree.file.info.objective);
    runtime_ = std::make_unique<CpuRuntime>(flattenBvh(tree.file.bvh),
                                            std::vector<uint32_t>(animation_.indices().begin(), animation_.indices().end()),
                                            animation_.vertexCount(), config);
    refit(animation_.startTime());
  }
  void refit(double time) {
    checkedTime(time, "time");
    py::gil_scoped_release release;
    runtime_->update(animation_.positionsAt(time));
  }
  void refitPositions(py::handle positions) { runtime_->update(checkedPositions(positions, runtime_->vertexCount())); }
  py::array trace(py::handle o, py::handle d, py::handle tmin, py::handle tmax) const {
    const std::vector<Ray> rays = makeRays(o, d, tmin, tmax);
    std::vector<Hit> hits;
    {
      py::gil_scoped_release release;
      hits = closestHits(*runtime_, rays);
    }
    return hitArray(std::move(hits));
  }
  py::array_t<bool> occluded(py::handle o, py::handle d, py::handle tmin, py::handle tmax) const {
    const std::vector<Ray> rays = makeRays(o, d, tmin, tmax);
    std::vector<uint8_t> flags;
    {
      py::gil_scoped_release release;
      flags = anyHits(*runtime_, rays);
    }
    return boolArray(flags);
  }
  std::string layout() const { return name(runtime_->layoutInfo().layout); }
  const CpuRuntime& runtime() const { return *runtime_; }
  py::array_t<float> bounds() const {
    const Aabb b = runtime_->bounds();
    py::array_t<float> out(std::vector<py::ssize_t>{2, 3});
    for (int a = 0; a < 3; ++a) {
      out.mutable_at(0, a) = b.lo[a];
      out.mutable_at(1, a) = b.hi[a];
    }
    return out;
  }

 private:
  anim::Animation animation_;
  std::unique_ptr<CpuRuntime> runtime_;
};

#if defined(TSAH_HAVE_CUDA)
// The same on the GPU: all keyframes uploaded once, refit and traversal on the device.
class GpuTracer {
 public:
  GpuTracer(const Tree& tree, const anim::Animation& animation, int device) {
    checkTreeMatchesAnimation(tree.file.info, "the tree", animation, "'" + animation.name() + "'");
    cuda::GpuRuntime::Config config;
    config.device = device;
    config.wideObjective = tree.file.info.objective;
    runtime_ = std::make_unique<cuda::GpuRuntime>(flattenBvh(tree.file.bvh), animation, config);
    refit(animation.startTime());
  }
  void refit(double time) {
    checkedTime(time, "time");
    py::gil_scoped_release release;
    runtime_->updateAt(time);
  }
  void refitPositions(py::handle positions) { runtime_->update(checkedPositions(positions, runtime_->vertexCount())); }
  py::array trace(py::handle o, py::handle d, py::handle tmin, py::handle tmax) {
    const std::vector<Ray> rays = makeRays(o, d, tmin, tmax);
    std::vector<Hit> hits;
    {
      py::gil_scoped_release release;
      hits = runtime_->closestHits(rays);
    }
    return hitArray(std::move(hits));
  }
  py::array_t<bool> occluded(py::handle o, py::handle d, py::handle tmin, py::handle tmax) {
    const std::vector<Ray> rays = makeRays(o, d, tmin, tmax);
    std::vector<uint8_t> flags;
    {
      py::gil_scoped_release release;
      flags = runtime_->anyHits(rays);
    }
    return boolArray(flags);
  }
  std::string deviceName() const { return runtime_->device().name; }
  cuda::GpuRuntime& runtime() { return *runtime_; }

 private:
  std::unique_ptr<cuda::GpuRuntime> runtime_;
};
#endif

namespace {

constexpr const char* kTraceDoc = R"doc(
Closest hits of rays against the current frame. origins, directions: float arrays (N, 3) (directions
need not be normalized; t is in units of the direction); tmin, tmax: numbers or arrays (N,).
Returns a numpy record array (N,) with fields t, u, v (float32) and triangle (int32: the triangle id
in the animation, -1 when the ray hits nothing); the hit point is (1-u-v)*v0 + u*v1 + v*v2.
)doc";
constexpr const char* kOccludedDoc =
    "True for each ray that hits anything within (tmin, tmax) (shadow / ambient-occlusion queries).";

}  // namespace

void bindRuntimes(py::module_& m) {
  const float inf = std::numeric_limits<float>::infinity();
  py::class_<CpuTracer>(m, "CpuRuntime", R"doc(
CpuRuntime(tree, animation, threads=0, layout="auto"): the tree refitted to a frame of the animation
it was built for (checked: triangle count, vertex count, topology), traced on the CPU. Starts at the
first frame. layout: "auto" (the widest layout this processor's SIMD kernels support, as `tsah
trace`), "bvh2", "bvh4" or "bvh8"; a wide layout is the tree collapsed with its own objective.
)doc")
      .def(py::init([](const Tree& tree, anim::Animation animation, py::handle threads, const std::string& layout) {
             return std::make_unique<CpuTracer>(tree, std::move(animation), checkedInteger<unsigned>(threads, "threads"),
                                                layout);
           }),
           "tree"_a, "animation"_a, "threads"_a = 0, "layout"_a = "auto")
      .def("refit", &CpuTracer::refit, "time"_a,
           "Refits the boxes to the animation at this time (interpolated, clamped) and recomputes the Woop triangles.")
      .def("refit_positions", &CpuTracer::refitPositions, "positions"_a,
           "Refits to given vertex positions, a float array (V, 3).")
      .def("trace", &CpuTracer::trace, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf, kTraceDoc)
      .def("occluded", &CpuTracer::occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           kOccludedDoc)
      .def_property_readonly("bounds", &CpuTracer::bounds, "Bounds of the current frame, float32 (2, 3).")
      .def_property_readonly("layout", &CpuTracer::layout, "The layout traced: bvh2, bvh4 or bvh8.");

#if defined(TSAH_HAVE_CUDA)
  m.attr("cuda_built") = true;
  m.def("cuda_available", &cuda::deviceAvailable, "True when the CUDA runtime was built and a GPU is present.");
  py::class_<GpuTracer>(m, "GpuRuntime", R"doc(
GpuRuntime(tree, animation, device=0): the same as CpuRuntime on a CUDA device (all keyframes are
uploaded once; refit and traversal run on the GPU). Raises tsah.Failure when no device is usable.
)doc")
      .def(py::init([](const Tree& tree, const anim::Animation& animation, py::handle device) {
             return std::make_unique<GpuTracer>(tree, animation, checkedInteger<int>(device, "device", 0));
           }),
           "tree"_a, "animation"_a, "device"_a = 0)
      .def("refit", &GpuTracer::refit, "time"_a, "Refits on the device to the animation at this time.")
      .def("refit_positions", &GpuTracer::refitPositions, "positions"_a, "Refits to given vertex positions (V, 3).")
      .def("trace", &GpuTracer::trace, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf, kTraceDoc)
      .def("occluded", &GpuTracer::occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           kOccludedDoc)
      .def_property_readonly("device_name", &GpuTracer::deviceName, "The name of the GPU the runtime uses.");
#else
  m.attr("cuda_built") = false;
  m.def("cuda_available", [] { return false; }, "True when the CUDA runtime was built and a GPU is present.");
#endif
}

const CpuRuntime& cpuRuntimeOf(py::handle self) { return self.cast<const CpuTracer&>().runtime(); }
#if defined(TSAH_HAVE_CUDA)
cuda::GpuRuntime& gpuRuntimeOf(py::handle self) { return self.cast<GpuTracer&>().runtime(); }
#endif

}  // namespace tsah::python
