// Runtimes in the Python module: a tree refitted to a frame of its animation, tracing numpy arrays
// of rays on the CPU (tsah::CpuRuntime) or the GPU (tsah::cuda::GpuRuntime, when built).
#include <pybind11/stl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <utility>

#include "anim/animation.hpp"
#include "bindings.hpp"
#include "device_arrays.hpp"
#include "host_rays.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/layout/flat_bvh.hpp"
#include "tsah/layout/wide_bvh.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/pipeline.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/render/renderer.hpp"
#include "tsah/base/coordinates.hpp"
#if defined(TSAH_HAVE_CUDA)
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#endif

namespace tsah::python {

namespace {

using namespace pybind11::literals;

// fn(begin, end) over [0, n) in chunks on the machine's hardware threads: the conversions between
// numpy and a batch (which the runtimes trace on all cores) would otherwise be serial beside it.
// fn must not throw.
template <class Fn>
void inParallel(std::size_t n, Fn&& fn) {
  constexpr std::size_t kChunk = std::size_t(1) << 16;  // below this a thread costs more than it saves
  const std::size_t threads = std::min<std::size_t>(std::max(1u, std::thread::hardware_concurrency()),
                                                    (n + kChunk - 1) / kChunk);
  if (threads <= 1) return fn(std::size_t(0), n);
  const std::size_t per = (n + threads - 1) / threads;
  std::vector<std::thread> pool;
  for (std::size_t t = 1; t < threads; ++t)
    pool.emplace_back([&fn, t, per, n] { fn(std::min(n, t * per), std::min(n, (t + 1) * per)); });
  fn(std::size_t(0), std::min(n, per));
  for (std::thread& thread : pool) thread.join();
}

// A float array (..., 3) as a C-contiguous (N, 3) float32 array, and its batch shape (the leading
// dimensions, the shape of the results).
struct Points {
  Array<float> rows;
  std::vector<py::ssize_t> batch;
};

Points checkedPoints(py::handle obj, const std::string& name) {
  if (py::isinstance<py::array>(obj)) {
    const auto a = py::reinterpret_borrow<py::array>(obj);
    if (a.ndim() < 1 || a.shape(a.ndim() - 1) != 3)
      throw tsah::ConfigError(name + ": expected shape (..., 3), got " + shapeText(a));
    std::vector<py::ssize_t> batch(a.shape(), a.shape() + a.ndim() - 1);
    const py::array rows = a.attr("reshape")(-1, 3);
    return {checkedArray<float>(rows, name, Kind::Float, {-1, 3}), std::move(batch)};
  }
  return {checkedArray<float>(obj, name, Kind::Float, {-1, 3}), {}};  // refused there: not an array
}

}  // namespace

std::unique_ptr<HostRays> hostRays(py::handle origins, py::handle directions, py::handle tmin, py::handle tmax) {
  auto rays = std::make_unique<HostRays>();
  Points org = checkedPoints(origins, "origins");
  Points dir = checkedPoints(directions, "directions");
  if (dir.batch != org.batch)
    throw tsah::ConfigError("directions: expected the shape of origins " + shapeText(py::reinterpret_borrow<py::array>(origins)) + ", got " +
                            shapeText(py::reinterpret_borrow<py::array>(directions)));
  rays->batch = std::move(org.batch);
  rays->origins = std::move(org.rows);
  rays->directions = std::move(dir.rows);
  const std::size_t n = std::size_t(rays->origins.shape(0));
  auto limit = [&](py::handle value, const char* name, std::optional<Array<float>>& array, float& number) {
    if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)) {
      number = value.cast<float>();
      return std::span<const float>(&number, 1);
    }
    py::object flat;  // holds a reshaped view while `value` refers to it
    if (py::isinstance<py::array>(value)) {
      const auto a = py::reinterpret_borrow<py::array>(value);
      if (std::vector<py::ssize_t>(a.shape(), a.shape() + a.ndim()) != rays->batch)
        throw tsah::ConfigError(std::string(name) + ": expected shape " + shapeText(rays->batch) + ", got " +
                                shapeText(a));
      flat = a.attr("reshape")(-1);
      value = flat;
    }
    array = checkedArray<float>(value, name, Kind::Number, {py::ssize_t(n)});
    return std::span<const float>(array->data(), n);
  };
  rays->arrays.tmin = limit(tmin, "tmin", rays->tmin, rays->tminValue);
  rays->arrays.tmax = limit(tmax, "tmax", rays->tmax, rays->tmaxValue);
  rays->arrays.origins = {rays->origins.data(), 3 * n};
  rays->arrays.directions = {rays->directions.data(), 3 * n};
  return rays;
}

// The rays of hostRays as Ray structs, checked (checkRays). Returns the rays and the batch shape.
RayBatch makeRays(py::handle origins, py::handle directions, py::handle tmin, py::handle tmax,
                  std::vector<py::ssize_t>& batch) {
  const std::unique_ptr<HostRays> host = hostRays(origins, directions, tmin, tmax);
  batch = host->batch;
  const RayArrays& arrays = host->arrays;
  const std::size_t n = arrays.size();
  RayBatch result{std::make_unique_for_overwrite<Ray[]>(n), n};
  Ray* rays = result.rays.get();
  std::atomic<bool> bad{false};
  inParallel(n, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) rays[i] = arrays.at(i);
    try {
      checkRays(std::span<const Ray>(rays + begin, end - begin));
    } catch (const tsah::ConfigError&) {
      bad = true;
    }
  });
  if (bad) checkRays(result);  // again over all of them: the message names the first bad ray
  return result;
}

namespace {

// The numpy record dtype of tsah::Hit.
py::dtype hitDtype() {
  static_assert(sizeof(Hit) == 16 && offsetof(Hit, tri) == 12);
  py::dict spec("names"_a = py::make_tuple("t", "u", "v", "triangle"),
                "formats"_a = py::make_tuple("<f4", "<f4", "<f4", "<i4"), "offsets"_a = py::make_tuple(0, 4, 8, 12),
                "itemsize"_a = 16);
  return py::dtype::from_args(spec);
}

}  // namespace

// The array results go to: the caller's `out` (checked: a writeable C-contiguous numpy array of
// `dtype` and the batch shape) or a new one.
py::array resultArray(py::handle out, const py::dtype& dtype, const std::vector<py::ssize_t>& batch) {
  if (out.is_none()) return py::array(dtype, batch);
  if (!py::isinstance<py::array>(out))
    throw ArgumentTypeError("out: expected a numpy array, got " + std::string(py::str(out.get_type().attr("__name__"))));
  auto a = py::reinterpret_borrow<py::array>(out);
  if (!a.dtype().equal(dtype))
    throw ArgumentTypeError("out: expected dtype " + std::string(py::str(py::handle(dtype))) + ", got " + std::string(py::str(a.dtype())));
  if (std::vector<py::ssize_t>(a.shape(), a.shape() + a.ndim()) != batch)
    throw tsah::ConfigError("out: expected shape " + shapeText(batch) + ", got " + shapeText(a));
  if (!(a.flags() & py::array::c_style)) throw tsah::ConfigError("out: must be C-contiguous");
  if (!a.writeable()) throw tsah::ConfigError("out: is read-only");
  return a;
}

namespace {

// tsah::Hit as a numpy record: t, u, v (float32) and triangle (int32, -1 when nothing was hit: the
// bits of tsah::kNoHit). A miss has t = inf (as in Embree and Warp) and u = v = 0.
py::array hitArray(const std::vector<Hit>& hits, py::array out) {
  Hit* p = static_cast<Hit*>(out.mutable_data());
  inParallel(hits.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      p[i] = hits[i].valid() ? hits[i] : Hit{std::numeric_limits<float>::infinity(), 0.0f, 0.0f, hits[i].tri};
  });
  return out;
}

}  // namespace

py::array boolArray(const std::vector<uint8_t>& flags, py::array out) {
  bool* p = static_cast<bool*>(out.mutable_data());
  inParallel(flags.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) p[i] = flags[i] != 0;
  });
  return out;
}

namespace {

// Vertex positions for a refit, a float32 array (V, 3) used in place (C-contiguous numpy; other
// float dtypes are converted). Coordinates that are NaN, infinite or beyond tsah::kMaxCoordinate
// are refused as anim::Animation refuses them (their boxes would make every ray visit every node).
Array<float> checkedPositions(py::handle positions, uint32_t vertices) {
  auto p = checkedArray<float>(positions, "positions", Kind::Float, {vertices, 3});
  const std::span<const float> values(p.data(), std::size_t(p.size()));
  if (const std::size_t bad = firstBadCoordinate(values); bad < values.size())
    throw tsah::DataError("positions: vertex " + std::to_string(bad / 3) + " " + describeBadCoordinate(values[bad]));
  return p;
}

// refit's argument: a time (a Python or numpy scalar number) or vertex positions (an array). torch
// and CuPy arrays implement the number protocol too (float(tensor)): they are positions.
bool isTime(py::handle value) {
  if (py::isinstance<py::bool_>(value)) return false;
  if (PyFloat_Check(value.ptr()) || PyLong_Check(value.ptr())) return true;  // without attribute lookups
  if (py::isinstance<py::array>(value)) return false;
  static const py::handle numpyNumber = py::object(py::module_::import("numpy").attr("number")).release();  // kept: numpy stays loaded
  if (py::isinstance(value, numpyNumber)) return true;
  // The protocols looked up on the class: reading torch's interface on the tensor builds it.
  const py::handle type = reinterpret_cast<PyObject*>(Py_TYPE(value.ptr()));
  return PyNumber_Check(value.ptr()) != 0 && !py::hasattr(type, "__cuda_array_interface__") &&
         !py::hasattr(type, "__dlpack__") && !py::hasattr(value, "__cuda_array_interface__");
}

// Wall time of the C++ batch call in its scope (the CPU runtime's RayPassStats: the batch call
// alone, without the conversions to and from numpy).
class PassClock {
 public:
  PassClock(RayPassStats& stats, std::size_t rays) : stats_(stats), rays_(rays) {}
  ~PassClock() {
    stats_.rays = rays_;
    stats_.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_).count();
  }
  PassClock(const PassClock&) = delete;
  PassClock& operator=(const PassClock&) = delete;

 private:
  RayPassStats& stats_;
  std::size_t rays_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

py::dict rayPassDict(const RayPassStats& s) { return py::dict("rays"_a = s.rays, "ms"_a = s.ms); }

}  // namespace

// The tree refitted to frames of its animation on the CPU.
class CpuTracer {
 public:
  // layout: "auto" (the widest this processor's SIMD kernels support, as `tsah trace`), "bvh2",
  // "bvh4" or "bvh8"; a wide layout is collapsed with the tree's own objective (its .tbvh header).
  // triangles: how a wide layout holds the frame's triangles, "woop" or "vertices" (TriangleForm).
  // Shares the caller's Animation (kept alive by holding its Python object) instead of copying it.
  CpuTracer(const Tree& tree, py::object animation, unsigned threads, const std::string& layout,
            const std::string& triangles)
      : owner_(std::move(animation)), animation_(owner_.cast<const anim::Animation&>()) {
    checkTreeMatchesAnimation(tree.file.info, "the tree", animation_, "'" + animation_.name() + "'");
    const CpuRuntime::Config config = runtimeConfig(threads, layout, triangles, tree.file.info.objective);
    runtime_ = std::make_unique<CpuRuntime>(flattenBvh(tree.file.bvh), indices(), animation_.vertexCount(), config);
    refitTime(animation_.startTime());
  }
  // A tree set: refit(time) refits and traces the tree of the time's part (TreeSet.tree_at), as
  // `tsah trace` does; each tree collapsed with its own objective in a wide layout.
  CpuTracer(const TreeSetObject& trees, py::object animation, unsigned threads, const std::string& layout,
            const std::string& triangles)
      : owner_(std::move(animation)), animation_(owner_.cast<const anim::Animation&>()) {
    for (uint32_t i = 0; i < trees.set.size(); ++i)
      checkTreeMatchesAnimation(trees.set.builds.at(i), "tree " + std::to_string(i) + " of the set", animation_,
                                "'" + animation_.name() + "'");
    const CpuRuntime::Config config = runtimeConfig(threads, layout, triangles, trees.set.builds.front().objective);
    runtime_ = std::make_unique<CpuRuntime>(trees.set, indices(), animation_.vertexCount(), config);
    refitTime(animation_.startTime());
  }
  void refit(py::handle timeOrPositions) {
    if (!isTime(timeOrPositions)) return refitPositions(timeOrPositions);
    refitTime(timeOrPositions.cast<double>());
  }
  void refitTime(double time) {
    checkedTime(time, "time");
    py::gil_scoped_release release;
    runtime_->selectTreeAt(time);  // a tree set: the tree of the time's part
    runtime_->update(animation_.positionsAt(time));
  }
  void refitPositions(py::handle vertices) {
    const Array<float> positions = checkedPositions(vertices, runtime_->vertexCount());
    py::gil_scoped_release release;
    runtime_->update(std::span<const float>(positions.data(), std::size_t(positions.size())));
  }
  // Each ray is made from the arrays, checked and traced in one task, its hit written straight into
  // the result (closestHits / anyHits of RayArrays): no batch of Ray structs or hits in between.
  py::array trace(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle out) const {
    const std::unique_ptr<HostRays> rays = hostRays(o, d, tmin, tmax);
    py::array result = resultArray(out, hitDtype(), rays->batch);
    const std::span<Hit> hits(static_cast<Hit*>(result.mutable_data()), rays->arrays.size());
    {
      py::gil_scoped_release release;
      const PassClock clock(lastPass_, hits.size());
      closestHits(*runtime_, rays->arrays, hits);
    }
    return result;
  }
  py::array occluded(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle out) const {
    const std::unique_ptr<HostRays> rays = hostRays(o, d, tmin, tmax);
    py::array result = resultArray(out, py::dtype::of<bool>(), rays->batch);
    static_assert(sizeof(bool) == 1);  // numpy's bool: one byte, 0 or 1
    const std::span<uint8_t> flags(static_cast<uint8_t*>(result.mutable_data()), rays->arrays.size());
    {
      py::gil_scoped_release release;
      const PassClock clock(lastPass_, flags.size());
      anyHits(*runtime_, rays->arrays, flags);
    }
    return result;
  }
  // tsah::closestHits (occluded: anyHits) on a batch of Ray structs made from the arrays beforehand
  // (the batch a C++ caller holding its own Ray array calls), its results as trace / occluded gives
  // them and the call's wall time (ms): the reference of python/bench/cpu_batch.py and the tests.
  py::tuple rayStructBatch(py::handle o, py::handle d, py::handle tmin, py::handle tmax, bool occluded) const {
    std::vector<py::ssize_t> batch;
    const RayBatch rays = makeRays(o, d, tmin, tmax, batch);
    std::vector<Hit> hits;
    std::vector<uint8_t> flags;
    std::chrono::steady_clock::duration took{};
    {
      py::gil_scoped_release release;
      const auto start = std::chrono::steady_clock::now();
      if (occluded)
        flags = anyHits(*runtime_, rays);
      else
        hits = closestHits(*runtime_, rays);
      took = std::chrono::steady_clock::now() - start;
    }
    const double ms = std::chrono::duration<double, std::milli>(took).count();
    if (occluded) return py::make_tuple(boolArray(flags, py::array(py::dtype::of<bool>(), batch)), ms);
    return py::make_tuple(hitArray(hits, py::array(hitDtype(), batch)), ms);
  }
  std::string layout() const { return name(runtime_->layoutInfo().layout); }
  std::string triangles() const { return name(runtime_->layoutInfo().triangles); }
  uint32_t treeIndex() const { return runtime_->currentTree(); }
  py::dict lastRayPass() const { return rayPassDict(lastPass_); }
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
  std::vector<uint32_t> indices() const { return {animation_.indices().begin(), animation_.indices().end()}; }
  static CpuRuntime::Config runtimeConfig(unsigned threads, const std::string& layout, const std::string& triangles,
                                          const Objective& objective) {
    CpuRuntime::Config config;
    config.threads = threads;
    config.layout = cpuLayoutArgument(layout);
    config.triangles = triangleFormArgument(triangles, "triangles");
    config.collapse = wideCollapseConfig(objective);
    return config;
  }

  py::object owner_;  // the tsah.Animation animation_ refers to
  const anim::Animation& animation_;
  std::unique_ptr<CpuRuntime> runtime_;
  mutable RayPassStats lastPass_;  // of the last trace / occluded
};

#if defined(TSAH_HAVE_CUDA)
// The same on the GPU: all keyframes uploaded once, refit and traversal on the device.
class GpuTracer {
 public:
  // layout: "auto" (the binary one: tsah::gpuLayout), "bvh2" or "cwbvh" (the compressed 8-wide
  // layout, collapsed with the tree's own objective).
  GpuTracer(const Tree& tree, const anim::Animation& animation, int device, const std::string& layout) {
    checkTreeMatchesAnimation(tree.file.info, "the tree", animation, "'" + animation.name() + "'");
    cuda::GpuRuntime::Config config = runtimeConfig(device, layout);
    config.wideObjective = tree.file.info.objective;
    runtime_ = std::make_unique<cuda::GpuRuntime>(flattenBvh(tree.file.bvh), animation, config);
    refitTime(animation.startTime());
  }
  // A tree set: refit(time) refits and traces the tree of the time's part, as CpuRuntime.
  GpuTracer(const TreeSetObject& trees, const anim::Animation& animation, int device, const std::string& layout) {
    for (uint32_t i = 0; i < trees.set.size(); ++i)
      checkTreeMatchesAnimation(trees.set.builds.at(i), "tree " + std::to_string(i) + " of the set", animation,
                                "'" + animation.name() + "'");
    runtime_ = std::make_unique<cuda::GpuRuntime>(trees.set, animation, runtimeConfig(device, layout));
    refitTime(animation.startTime());
  }
  void refit(py::handle timeOrPositions, py::handle stream, bool wait) {
    const InterfaceReadScope reads;
    if (!isTime(timeOrPositions)) return refitPositions(timeOrPositions, stream, wait);
    refitTime(timeOrPositions.cast<double>());
  }
  void refitTime(double time) {
    checkedTime(time, "time");
    py::gil_scoped_release release;
    lastUpdate_ = runtime_->updateAt(time);
  }
  void refitPositions(py::handle vertices, py::handle stream, bool wait) {
    if (isDeviceArray(vertices)) return refitDevice(vertices, streamArgument(stream), wait);
    const Array<float> positions = checkedPositions(vertices, runtime_->vertexCount());
    py::gil_scoped_release release;
    lastUpdate_ = runtime_->update(std::span<const float>(positions.data(), std::size_t(positions.size())));
  }
  py::object trace(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle out, py::handle stream) {
    const InterfaceReadScope reads;
    if (isDeviceArray(o) || isDeviceArray(d)) return traceDevice(o, d, tmin, tmax, out, streamArgument(stream));
    std::vector<py::ssize_t> batch;
    const RayBatch rays = makeRays(o, d, tmin, tmax, batch);
    py::array result = resultArray(out, hitDtype(), batch);
    std::vector<Hit> hits;
    {
      py::gil_scoped_release release;
      hits = runtime_->closestHits(rays, &lastPass_);
    }
    return hitArray(hits, result);
  }
  py::object occluded(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle out, py::handle stream) {
    const InterfaceReadScope reads;
    if (isDeviceArray(o) || isDeviceArray(d)) return occludedDevice(o, d, tmin, tmax, out, streamArgument(stream));
    std::vector<py::ssize_t> batch;
    const RayBatch rays = makeRays(o, d, tmin, tmax, batch);
    py::array result = resultArray(out, py::dtype::of<bool>(), batch);
    std::vector<uint8_t> flags;
    {
      py::gil_scoped_release release;
      flags = runtime_->anyHits(rays, &lastPass_);
    }
    return boolArray(flags, result);
  }
  void check() {
    py::gil_scoped_release release;
    runtime_->checkDeviceUpdate();
  }
  std::string deviceName() const { return runtime_->device().name; }
  std::string layout() const { return name(runtime_->config().layout); }
  uint32_t treeIndex() const { return runtime_->currentTree(); }
  cuda::GpuRuntime& runtime() { return *runtime_; }
  py::dict lastUpdate() const {
    return py::dict("interpolate_ms"_a = lastUpdate_.interpolateMs, "refit_ms"_a = lastUpdate_.refitMs,
                    "woop_ms"_a = lastUpdate_.woopMs, "total_ms"_a = lastUpdate_.totalMs());
  }
  py::dict lastRayPass() const { return rayPassDict(lastPass_); }

 private:
  int device() const { return runtime_->config().device; }
  static cuda::GpuRuntime::Config runtimeConfig(int device, const std::string& layout) {
    cuda::GpuRuntime::Config config;
    config.device = device;
    config.layout = gpuLayoutArgument(layout);
    return config;
  }
  void refitDevice(py::handle vertices, std::uintptr_t stream, bool wait) {
    DeviceArguments args(device(), stream);
    const uint32_t v = runtime_->vertexCount();
    const float* positions = pointerOf<const float>(args.add(vertices, "positions", {"<f4"}, {py::ssize_t(v), 3}));
    args.waitForProducers();
    py::gil_scoped_release release;
    runtime_->updateFromDevice(positions, v, reinterpret_cast<void*>(stream),
                               wait ? cuda::GpuRuntime::DeviceCheck::Wait : cuda::GpuRuntime::DeviceCheck::Deferred);
  }
  py::object traceDevice(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle out,
                         std::uintptr_t stream) {
    DeviceArguments args(device(), stream);
    std::vector<py::ssize_t> batch;
    const cuda::GpuRuntime::DeviceRays rays = deviceRays(args, o, d, tmin, tmax, batch);
    static const std::vector<DeviceHitField> kFields = {
        {"t", "<f4", {"<f4"}}, {"u", "<f4", {"<f4"}}, {"v", "<f4", {"<f4"}}, {"triangle", "<i4", {"<i4", "<u4"}}};
    std::vector<void*> p;
    const py::dict results = deviceHitArrays(args, out, kFields, batch, device(), p);
    const cuda::GpuRuntime::DeviceHits hits{static_cast<float*>(p[0]), static_cast<float*>(p[1]),
                                            static_cast<float*>(p[2]), static_cast<uint32_t*>(p[3])};
    args.waitForProducers();
    {
      py::gil_scoped_release release;
      runtime_->closestHitsOnDevice(rays, hits, reinterpret_cast<void*>(stream));
    }
    return results;
  }
  py::object occludedDevice(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle out,
                            std::uintptr_t stream) {
    DeviceArguments args(device(), stream);
    std::vector<py::ssize_t> batch;
    const cuda::GpuRuntime::DeviceRays rays = deviceRays(args, o, d, tmin, tmax, batch);
    uint8_t* flags = nullptr;
    const py::object result = deviceFlagArray(args, out, batch, device(), &flags);
    args.waitForProducers();
    {
      py::gil_scoped_release release;
      runtime_->anyHitsOnDevice(rays, flags, reinterpret_cast<void*>(stream));
    }
    return result;
  }

  std::unique_ptr<cuda::GpuRuntime> runtime_;
  cuda::UpdateTimings lastUpdate_;
  RayPassStats lastPass_;
};
#endif

namespace {

constexpr const char* kRefitDoc = R"doc(
refit(time) (a float): refits to the animation at this time (interpolated, clamped). refit(positions): refits to
these vertex positions, a float array (V, 3) (float32 is used in place); every coordinate must be
finite and within 1e18, as in an imported animation. The GIL is released while the refit runs.
)doc";
constexpr const char* kTraceDoc = R"doc(
Closest hits of rays against the current frame. origins, directions: float arrays (..., 3) of one
shape (directions need not be normalized; t is in units of the direction); tmin, tmax: numbers or
arrays of the batch shape (...). Returns a numpy record array of the batch shape with fields t, u, v
(float32) and triangle (int32: the triangle id in the animation, -1 when the ray hits nothing; t is
inf then); the hit point is (1-u-v)*v0 + u*v1 + v*v2. out: a C-contiguous array of that dtype and
shape to write into (returned). The GIL is released while tracing.
)doc";
constexpr const char* kOccludedDoc =
    "True for each ray that hits anything within (tmin, tmax) (shadow / ambient-occlusion queries); a bool "
    "array of the batch shape, or written into out= (bool, C-contiguous).";
constexpr const char* kDeviceDoc = R"doc(
Device arrays (objects with __cuda_array_interface__ or a CUDA __dlpack__, e.g. torch or CuPy
arrays on the runtime's device; float32, C-contiguous) are used in place: refit(positions) checks
them on the device; trace returns a dict of tsah.DeviceArray t, u, v (float32) and triangle
(int32) of the batch shape, occluded a bool tsah.DeviceArray, or they write into out= (a dict of
device arrays for trace, any of its four fields; a bool or uint8 device array for occluded). The
work is ordered after what the caller queued on `stream` (None: the legacy default stream; an int
cudaStream_t, or an object with __cuda_stream__ or cuda_stream) and before what it queues there
next; device traces do not wait for the device (synchronize the stream before reading on the host).
refit(positions, wait=False) does not wait for the device either: a device array with a bad
coordinate is refused on the device (the frame stays as it was) and the DataError is raised by the
next refit (of any kind) or check() call; see docs/python.md#device-arrays.
)doc";
constexpr const char* kLastRayPassDoc =
    "The last host-array trace or occluded call: {'rays': count, 'ms': time of the library's batch alone (GPU: the "
    "traversal kernel's device time; CPU: the C++ batch call's wall time)}.";

}  // namespace

void bindRuntimes(py::module_& m) {
  const float inf = std::numeric_limits<float>::infinity();
  py::class_<CpuTracer>(m, "CpuRuntime", R"doc(
CpuRuntime(tree, animation, threads=0, layout="auto", triangles="woop"): the tree refitted to a
frame of the animation it was built for (checked: triangle count, vertex count, topology), traced on
the CPU. Starts at the first frame. layout: "auto" (the widest layout this processor's SIMD kernels
support, as `tsah trace`), "bvh2", "bvh4" or "bvh8"; a wide layout is the tree collapsed with its
own objective. triangles: how a wide layout holds each frame's triangles, "woop" (Woop packets) or
"vertices" (vertex packets: the refit computes no Woop rows; docs/wide-bvh.md); bvh2 holds Woop
triangles only.
tree may be a tsah.TreeSet: refit(time) then refits and traces the tree of the time's part
(TreeSet.tree_at; tree_index says which), refit(positions) the tree of the last refit(time).
)doc")
      .def(py::init([](const Tree& tree, py::object animation, py::handle threads, const std::string& layout,
                       const std::string& triangles) {
             return std::make_unique<CpuTracer>(tree, std::move(animation), checkedInteger<unsigned>(threads, "threads"),
                                                layout, triangles);
           }),
           "tree"_a, "animation"_a, "threads"_a = 0, "layout"_a = "auto", "triangles"_a = "woop")
      .def(py::init([](const TreeSetObject& trees, py::object animation, py::handle threads, const std::string& layout,
                       const std::string& triangles) {
             return std::make_unique<CpuTracer>(trees, std::move(animation), checkedInteger<unsigned>(threads, "threads"),
                                                layout, triangles);
           }),
           "tree"_a, "animation"_a, "threads"_a = 0, "layout"_a = "auto", "triangles"_a = "woop")
      .def_property_readonly("tree_index", &CpuTracer::treeIndex,
                             "The index of the tree traced in a tree set (chosen by the last refit(time)); 0 for a tree.")
      .def("refit", &CpuTracer::refit, "time"_a, kRefitDoc)
      .def("refit_positions", &CpuTracer::refitPositions, "positions"_a, "The same as refit(positions) (vertex positions only).")
      .def("trace", &CpuTracer::trace, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "out"_a = py::none(), kTraceDoc)
      .def("occluded", &CpuTracer::occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "out"_a = py::none(), kOccludedDoc)
      .def_property_readonly("bounds", &CpuTracer::bounds, "Bounds of the current frame, float32 (2, 3).")
      .def_property_readonly("layout", &CpuTracer::layout, "The layout traced: bvh2, bvh4 or bvh8.")
      .def_property_readonly("triangles", &CpuTracer::triangles,
                             "How the traced tree holds the frame's triangles: woop or vertices.")
      .def_property_readonly("last_ray_pass", &CpuTracer::lastRayPass, kLastRayPassDoc)
      .def("_ray_struct_batch", &CpuTracer::rayStructBatch, "origins"_a, "directions"_a, "tmin"_a = 0.0f,
           "tmax"_a = inf, "occluded"_a = false,
           "(results, ms): tsah::closestHits (occluded: anyHits) of the C++ API on Ray structs made from the "
           "arrays beforehand, and its wall time (the reference of python/bench/cpu_batch.py).");

#if defined(TSAH_HAVE_CUDA)
  m.attr("cuda_built") = true;
  m.def("cuda_available", &cuda::deviceAvailable, "True when the CUDA runtime was built and a GPU is present.");
  py::class_<GpuTracer>(m, "GpuRuntime", R"doc(
GpuRuntime(tree, animation, device=0, layout="auto"): the same as CpuRuntime on a CUDA device (all
keyframes are uploaded once; refit and traversal run on the GPU). layout: "auto" (the binary layout,
the faster GPU layout on the data scenes), "bvh2" or "cwbvh" (compressed 8-wide nodes). Raises
tsah.Failure when no device is usable.
)doc")
      .def(py::init([](const Tree& tree, const anim::Animation& animation, py::handle device, const std::string& layout) {
             return std::make_unique<GpuTracer>(tree, animation, checkedInteger<int>(device, "device", 0), layout);
           }),
           "tree"_a, "animation"_a, "device"_a = 0, "layout"_a = "auto")
      .def(py::init([](const TreeSetObject& trees, const anim::Animation& animation, py::handle device,
                       const std::string& layout) {
             return std::make_unique<GpuTracer>(trees, animation, checkedInteger<int>(device, "device", 0), layout);
           }),
           "tree"_a, "animation"_a, "device"_a = 0, "layout"_a = "auto")
      .def_property_readonly("layout", &GpuTracer::layout, "The layout traced: bvh2 or cwbvh.")
      .def_property_readonly("tree_index", &GpuTracer::treeIndex,
                             "The index of the tree traced in a tree set (chosen by the last refit(time)); 0 for a tree.")
      .def("refit", &GpuTracer::refit, "time"_a, py::kw_only(), "stream"_a = py::none(), "wait"_a = true,
           (std::string(kRefitDoc) + kDeviceDoc).c_str())
      .def("refit_positions", &GpuTracer::refitPositions, "positions"_a, py::kw_only(), "stream"_a = py::none(),
           "wait"_a = true, "The same as refit(positions) (vertex positions only).")
      .def("check", &GpuTracer::check,
           "Waits for the check of the last refit(device positions, wait=False) if it is still running and raises "
           "its tsah.DataError when it refused the frame (each refusal is raised once).")
      .def("trace", &GpuTracer::trace, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "out"_a = py::none(), py::kw_only(), "stream"_a = py::none(), (std::string(kTraceDoc) + kDeviceDoc).c_str())
      .def("occluded", &GpuTracer::occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "out"_a = py::none(), py::kw_only(), "stream"_a = py::none(), (std::string(kOccludedDoc) + kDeviceDoc).c_str())
      .def_property_readonly("device_name", &GpuTracer::deviceName, "The name of the GPU the runtime uses.")
      .def_property_readonly("last_ray_pass", &GpuTracer::lastRayPass, kLastRayPassDoc)
      .def_property_readonly("last_update", &GpuTracer::lastUpdate,
                             "Device time of the last refit from a time or host positions (ms): interpolate_ms (the "
                             "upload for positions), refit_ms, woop_ms, total_ms.");
#else
  m.attr("cuda_built") = false;
  m.def("cuda_available", [] { return false; }, "True when the CUDA runtime was built and a GPU is present.");
#endif
}

Layout cpuLayoutArgument(const std::string& layout) {
  const Layout chosen = parse<Layout>(layout);
  if (chosen == Layout::Cwbvh) throw tsah::ConfigError("layout: cwbvh is a GPU layout (the CPU's are bvh2, bvh4, bvh8)");
  return chosen == Layout::Auto ? fastestLayout() : chosen;
}

Layout gpuLayoutArgument(const std::string& layout) {
  const Layout chosen = gpuLayout(parse<Layout>(layout));
  if (chosen != Layout::Bvh2 && chosen != Layout::Cwbvh)
    throw tsah::ConfigError("layout: " + layout + " is a CPU layout (the GPU's are bvh2 and cwbvh)");
  return chosen;
}

TriangleForm triangleFormArgument(const std::string& form, const char* argument) {
  try {
    return parse<TriangleForm>(form);
  } catch (const tsah::ConfigError& e) {
    throw tsah::ConfigError(std::string(argument) + ": " + e.what());
  }
}

const CpuRuntime& cpuRuntimeOf(py::handle self) { return self.cast<const CpuTracer&>().runtime(); }
#if defined(TSAH_HAVE_CUDA)
cuda::GpuRuntime& gpuRuntimeOf(py::handle self) { return self.cast<GpuTracer&>().runtime(); }
#endif

}  // namespace tsah::python
