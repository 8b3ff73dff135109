// Two-level scenes in the Python module (docs/two-level.md, docs/python.md#two-level-scenes):
// tsah.TwoLevelScene (load_two_level; build_two_level, the library steps of `tsah optimize
// --structure`), traced from numpy rays by tsah.TwoLevelRuntime (tsah::TwoLevelRuntime, motion blur
// included) and, in CUDA builds, tsah.GpuTwoLevelRuntime (tsah::cuda::GpuTwoLevelRuntime).
#include <pybind11/stl.h>

#include <cmath>
#include <cstddef>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "anim/scene.hpp"
#include "bindings.hpp"
#include "host_rays.hpp"
#include "tsah/core/kinds.hpp"
#include "tsah/runtime/cpu_runtime.hpp"
#include "tsah/scene/structure_choice.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah/scene/two_level_runtime.hpp"
#if defined(TSAH_HAVE_CUDA)
#include "device_arrays.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#endif

namespace tsah::python {

// A two-level scene as the module hands it out: the structure, and for one built with
// structure="auto" the decision that flattened some of its objects.
struct TwoLevelSceneObject {
  TwoLevelScene scene;
  std::optional<StructureChoice> choice;
  std::string scenePath;  // the scene file, absolute: what an unpickled copy loads its sources from
};

namespace {

using namespace pybind11::literals;

// Loads a scene file's sources with the importers' warnings collected (raised as UserWarnings by
// warnAll once the GIL is held again).
anim::SceneSources loadSources(const std::string& path, std::vector<std::string>& warnings) {
  anim::LoadOptions load;
  load.warning = [&warnings](const std::string& w) { warnings.push_back(w); };
  return anim::loadSceneSources(path, load);
}

void warnAll(const std::vector<std::string>& warnings) {
  for (const std::string& w : warnings) PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1);
}

TwoLevelSceneObject loadTwoLevel(py::handle treeArg, py::handle sceneArg) {
  const std::string tree = pathArgument(treeArg, "tree_path"), scene = pathArgument(sceneArg, "scene_path");
  std::vector<std::string> warnings;
  // The importers and the file check take no cancel check: Ctrl-C is raised when the load returns.
  TwoLevelScene loaded = LongCall().run([&] { return loadTwoLevelSceneFile(tree, loadSources(scene, warnings)); });
  warnAll(warnings);
  return {std::move(loaded), std::nullopt, std::filesystem::absolute(scene).string()};
}

// What `tsah optimize SCENE --structure auto|two-level` builds (the command line's library steps):
// auto flattens the objects chooseObjectStructure picks (with the trees' cT, cI and leaf size), then
// buildTwoLevelScene. When auto flattens every object (the command line then writes a flat tree),
// the scene is one instance of the flattened source.
TwoLevelSceneObject buildTwoLevel(py::handle sceneArg, const std::string& structure, py::handle k, py::handle frames,
                                  const std::string& selection, py::handle seed, float ct, float ci,
                                  py::handle maxLeaf, double timeLimit, double minImprovement, py::handle threads,
                                  const std::string& optimizer, py::handle tlasTrees, double tlasBudget,
                                  py::object progress) {
  const std::string path = pathArgument(sceneArg, "scene_path");
  TlasOptions tlas;
  tlas.budget = tlasBudget;
  if (!(py::isinstance<py::str>(tlasTrees) && tlasTrees.cast<std::string>() == "auto")) {
    if (!py::isinstance<py::int_>(tlasTrees) || py::isinstance<py::bool_>(tlasTrees) || tlasTrees.cast<long long>() < 1)
      throw tsah::ConfigError("tlas_trees: expected 'auto' or a number of trees >= 1, got " +
                              py::repr(tlasTrees).cast<std::string>());
    const long long trees = tlasTrees.cast<long long>();
    if (trees > TlasOptions::kMaxTrees)
      throw tsah::ConfigError("tlas_trees: " + std::to_string(trees) + " is more than " +
                              std::to_string(TlasOptions::kMaxTrees));
    tlas.trees = uint32_t(trees);
  }
  tlas.validate();
  if (structure != "auto" && structure != "two-level")
    throw tsah::ConfigError("structure: expected 'auto' or 'two-level', got '" + structure +
                            "' (a flat tree of a scene file: tsah.optimize(tsah.load(scene_path)))");
  if (optimizer != "sequential" && optimizer != "parallel")
    throw tsah::ConfigError("optimizer: a two-level scene is built on the CPU: 'sequential' or 'parallel', not '" +
                            optimizer + "'");
  TreeOptions options = treeOptions("tsah", k, frames, selection, seed, ct, ci, maxLeaf, timeLimit, minImprovement,
                                    threads, optimizer);
  LongCall call(std::move(progress));
  connect(options, call, false);
  std::vector<std::string> warnings;
  TwoLevelSceneObject built = call.run([&] {
    anim::SceneSources sources = loadSources(path, warnings);
    std::optional<StructureChoice> choice;
    if (structure == "auto") {
      choice = chooseObjectStructure(sources, structureChoiceOptions(options.objective));
      sources = anim::flattenObjects(std::move(sources), choice->flattenedObjects);
    }
    return TwoLevelSceneObject{buildTwoLevelScene(std::move(sources), options, tlas), std::move(choice),
                               std::filesystem::absolute(path).string()};
  });
  warnAll(warnings);
  return built;
}

py::list flattenedNames(const TwoLevelScene& s) {
  py::list names;
  for (uint32_t o : s.scene.flattenedObjects) names.append(s.scene.description.objects[o].name);
  return names;
}

py::dict choiceDict(const StructureChoice& choice) {
  py::list objects;
  for (const ObjectStructureChoice& c : choice.objects) {
    py::dict o("object"_a = c.object, "name"_a = c.name, "instances"_a = c.instances, "moves"_a = c.moves,
               "flatten"_a = c.flatten, "flattened_triangles"_a = c.flattenedTriangles, "reason"_a = c.reason);
    if (c.instancedCost >= 0.0) o["cost"] = py::dict("instanced"_a = c.instancedCost, "flattened"_a = c.flattenedCost);
    objects.append(o);
  }
  py::dict out("flattened_objects"_a = choice.flattenedObjects, "representative_frames"_a = choice.frames,
               "seconds"_a = choice.seconds, "objects"_a = objects);
  if (choice.decidedCost >= 0.0)
    out["whole_scene_cost"] = py::dict("flattened"_a = choice.wholeFlattenedCost, "decided"_a = choice.decidedCost);
  return out;
}

// The fields of `tsah info TREE SCENE --json` for a two-level tree, plus the TLAS header's options.
py::dict infoDict(const TwoLevelSceneObject& object) {
  const TwoLevelScene& s = object.scene;
  py::list blases;
  for (const Blas& b : s.blases) {
    const anim::Animation& source = *s.scene.sources[b.source];
    blases.append(py::dict("source"_a = b.source, "name"_a = source.name(), "animated"_a = b.animated,
                           "triangles"_a = source.triangleCount(), "keyframes"_a = source.keyframeCount(),
                           "nodes"_a = b.bvh.nodeCount(), "build_frames"_a = b.frameCosts.size(), "cost"_a = b.cost));
  }
  py::list tlasRanges;
  uint64_t tlasNodes = 0;
  for (const TlasTree& t : s.tlases) {
    tlasRanges.append(py::make_tuple(t.range.start, t.range.end));
    tlasNodes += t.bvh.nodeCount();
  }
  py::dict info("flattened_objects"_a = flattenedNames(s), "instances"_a = s.instanceCount(),
                "poses"_a = s.poses.size(), "scene_frames"_a = s.frameTimes.size(), "k"_a = s.objective.k,
                "ct"_a = s.objective.cost.ct, "ci"_a = s.objective.cost.ci, "max_leaf_size"_a = s.objective.maxLeafSize,
                "tlas"_a = py::dict("trees"_a = s.tlases.size(), "nodes"_a = tlasNodes, "ranges"_a = tlasRanges,
                                    "cost"_a = s.tlasCost,
                                    "frame_costs"_a = doubleArray(s.tlasFrameCosts)),
                "blases"_a = blases,
                "bytes"_a = py::dict("blas"_a = s.blasBytes(), "tlas"_a = s.tlasBytes(), "total"_a = s.memoryBytes()));
  if (object.choice) info["structure_choice"] = choiceDict(*object.choice);
  return info;
}

// The numpy record dtype of tsah::TwoLevelHit: t, u, v (float32), instance and triangle (int32, -1
// for a miss: the bits of tsah::kNoHit).
py::dtype twoLevelHitDtype() {
  static_assert(sizeof(TwoLevelHit) == 20 && offsetof(TwoLevelHit, prim) == 16);
  py::dict spec("names"_a = py::make_tuple("t", "u", "v", "instance", "triangle"),
                "formats"_a = py::make_tuple("<f4", "<f4", "<f4", "<i4", "<i4"),
                "offsets"_a = py::make_tuple(0, 4, 8, 12, 16), "itemsize"_a = 20);
  return py::dtype::from_args(spec);
}

// A hit as Python sees it: a miss has t = inf and u = v = 0 (as CpuRuntime.trace's misses).
TwoLevelHit shown(const TwoLevelHit& hit) {
  return hit.valid() ? hit : TwoLevelHit{std::numeric_limits<float>::infinity(), 0.0f, 0.0f, kNoHit, kNoHit};
}

// times=: None, a number (every ray) or a float array (or sequence) of the batch shape, each finite: the rays'
// shutter fractions (as float32, flattened).
std::optional<Array<float>> rayTimes(py::handle times, const std::vector<py::ssize_t>& batch, std::size_t n) {
  if (times.is_none()) return std::nullopt;
  py::object value = py::reinterpret_borrow<py::object>(times);
  const py::module_ numpy = py::module_::import("numpy");
  if (py::isinstance<py::float_>(times) || py::isinstance<py::int_>(times) || py::isinstance(times, numpy.attr("number"))) {
    if (py::isinstance<py::bool_>(times)) throw ArgumentTypeError("times: expected a number or a float array, got bool");
    value = numpy.attr("full")(py::int_(n), times, "float32");
  } else if (value = arrayArgument(times, "times", Kind::Float); py::isinstance<py::array>(value)) {
    const auto a = py::reinterpret_borrow<py::array>(value);
    if (std::vector<py::ssize_t>(a.shape(), a.shape() + a.ndim()) != batch)
      throw tsah::ConfigError("times: expected shape " + shapeText(batch) + ", got " + shapeText(a));
    value = a.attr("reshape")(-1);
  }
  Array<float> t = checkedArray<float>(value, "times", Kind::Number, {py::ssize_t(n)});
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(t.data()[i]))
      throw tsah::ConfigError("times: value " + std::string(py::str(py::float_(t.data()[i]))) + " (index " +
                              std::to_string(i) + ") is not a finite shutter fraction");
  return t;
}

py::array_t<float> boxesArray(std::span<const Aabb> boxes) {
  py::array_t<float> out(std::vector<py::ssize_t>{py::ssize_t(boxes.size()), 2, 3});
  auto view = out.mutable_unchecked<3>();
  for (std::size_t i = 0; i < boxes.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      view(py::ssize_t(i), 0, a) = boxes[i].lo[a];
      view(py::ssize_t(i), 1, a) = boxes[i].hi[a];
    }
  return out;
}

constexpr std::size_t kRaysPerTask = 1024;

// The scene argument of the runtimes: a constructed tsah.TwoLevelScene (ArgumentTypeError otherwise).
const TwoLevelSceneObject& sceneArgument(py::handle scene) {
  if (!py::isinstance<TwoLevelSceneObject>(scene))
    throw ArgumentTypeError("scene: expected a tsah.TwoLevelScene, got " +
                            std::string(py::str(scene.get_type().attr("__name__"))));
  return scene.cast<const TwoLevelSceneObject&>();
}

}  // namespace

// The CPU runtime of a scene (kept alive through its Python object).
class TwoLevelTracer {
 public:
  TwoLevelTracer(py::object scene, unsigned threads, const std::string& layout, const std::string& tlas,
                 const std::string& poseTriangles)
      : owner_(std::move(scene)), scene_(sceneArgument(owner_).scene) {
    const Layout chosen = cpuLayoutArgument(layout);
    if (tlas != "refit" && tlas != "rebuild")
      throw tsah::ConfigError("tlas: expected 'refit' or 'rebuild', got '" + tlas + "'");
    TwoLevelRuntime::Config config;
    config.threads = threads;
    config.layout = chosen;
    config.poseTriangles = triangleFormArgument(poseTriangles, "pose_triangles");
    config.tlas = tlas == "refit" ? TwoLevelRuntime::TlasUpdate::Refit : TwoLevelRuntime::TlasUpdate::Rebuild;
    py::gil_scoped_release release;
    runtime_ = std::make_unique<TwoLevelRuntime>(scene_, config);
  }
  void update(double time) {
    checkedTime(time, "time");
    py::gil_scoped_release release;
    runtime_->update(time);
  }
  void updateShutter(double open, double close) {
    checkedTime(open, "open");
    checkedTime(close, "close");
    py::gil_scoped_release release;
    runtime_->updateShutter(open, close);
  }
  py::array trace(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle times, py::handle out) const {
    std::vector<py::ssize_t> batch;
    const RayBatch rays = makeRays(o, d, tmin, tmax, batch);
    const std::optional<Array<float>> t = rayTimes(times, batch, rays.count);
    py::array result = resultArray(out, twoLevelHitDtype(), batch);
    auto* hits = static_cast<TwoLevelHit*>(result.mutable_data());
    const float* time = t ? t->data() : nullptr;
    {
      py::gil_scoped_release release;
      runtime_->parallelFor(rays.count, kRaysPerTask, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i)
          hits[i] = shown(time ? runtime_->closestHit(rays.rays[i], time[i]) : runtime_->closestHit(rays.rays[i]));
      });
    }
    return result;
  }
  py::array occluded(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle times,
                     py::handle out) const {
    std::vector<py::ssize_t> batch;
    const RayBatch rays = makeRays(o, d, tmin, tmax, batch);
    const std::optional<Array<float>> t = rayTimes(times, batch, rays.count);
    py::array result = resultArray(out, py::dtype::of<bool>(), batch);
    auto* flags = static_cast<bool*>(result.mutable_data());
    const float* time = t ? t->data() : nullptr;
    {
      py::gil_scoped_release release;
      runtime_->parallelFor(rays.count, kRaysPerTask, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i)
          flags[i] = time ? runtime_->anyHit(rays.rays[i], time[i]) : runtime_->anyHit(rays.rays[i]);
      });
    }
    return result;
  }
  const TwoLevelRuntime& runtime() const { return *runtime_; }

 private:
  py::object owner_;  // the tsah.TwoLevelScene scene_ belongs to
  const TwoLevelScene& scene_;
  std::unique_ptr<TwoLevelRuntime> runtime_;
};

#if defined(TSAH_HAVE_CUDA)
// The same on the GPU, from host rays.
class GpuTwoLevelTracer {
 public:
  GpuTwoLevelTracer(py::object scene, int device, const std::string& layout, const std::string& tlas)
      : owner_(std::move(scene)), scene_(sceneArgument(owner_).scene) {
    cuda::GpuTwoLevelRuntime::Config config;
    config.device = device;
    config.layout = gpuLayoutArgument(layout);
    try {
      config.tlas = cuda::parseTlasUpdate(tlas);
    } catch (const tsah::ConfigError& e) {
      throw tsah::ConfigError(std::string("tlas: ") + e.what());  // the argument's name first
    }
    py::gil_scoped_release release;
    runtime_ = std::make_unique<cuda::GpuTwoLevelRuntime>(scene_, config);
  }
  void update(double time) {
    checkedTime(time, "time");
    py::gil_scoped_release release;
    lastUpdate_ = runtime_->updateAt(time);
  }
  void updateShutter(double open, double close) {
    checkedTime(open, "open");
    checkedTime(close, "close");
    py::gil_scoped_release release;
    runtime_->updateShutter(open, close);
  }
  py::object trace(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle times, py::handle out,
                   py::handle stream) {
    const InterfaceReadScope reads;
    if (isDeviceArray(o) || isDeviceArray(d)) return traceDevice(o, d, tmin, tmax, times, out, streamArgument(stream));
    std::vector<py::ssize_t> batch;
    const RayBatch rays = makeRays(o, d, tmin, tmax, batch);
    const std::optional<Array<float>> t = rayTimes(times, batch, rays.count);
    py::array result = resultArray(out, twoLevelHitDtype(), batch);
    auto* hits = static_cast<TwoLevelHit*>(result.mutable_data());
    {
      py::gil_scoped_release release;
      const std::vector<TwoLevelHit> found =
          t ? runtime_->closestHits(rays, std::span<const float>(t->data(), rays.count)) : runtime_->closestHits(rays);
      for (std::size_t i = 0; i < found.size(); ++i) hits[i] = shown(found[i]);
    }
    return result;
  }
  py::object occluded(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle times, py::handle out,
                      py::handle stream) {
    const InterfaceReadScope reads;
    if (isDeviceArray(o) || isDeviceArray(d)) return occludedDevice(o, d, tmin, tmax, times, out, streamArgument(stream));
    std::vector<py::ssize_t> batch;
    const RayBatch rays = makeRays(o, d, tmin, tmax, batch);
    const std::optional<Array<float>> t = rayTimes(times, batch, rays.count);
    py::array result = resultArray(out, py::dtype::of<bool>(), batch);
    std::vector<uint8_t> flags;
    {
      py::gil_scoped_release release;
      flags = t ? runtime_->anyHits(rays, std::span<const float>(t->data(), rays.count)) : runtime_->anyHits(rays);
    }
    return boolArray(flags, result);
  }
  bool blurred() const { return runtime_->blurred(); }
  double time() const { return runtime_->time(); }
  std::string deviceName() const { return runtime_->device().name; }
  py::dict lastUpdate() const {
    const cuda::TwoLevelUpdateTimings& u = lastUpdate_;
    return py::dict("upload_ms"_a = u.uploadMs, "blas_ms"_a = u.blasMs, "tlas_ms"_a = u.tlasMs,
                    "tlas_rebuild_ms"_a = u.tlasRebuildMs, "total_ms"_a = u.totalMs(), "blas_refits"_a = u.blasRefits,
                    "instances"_a = u.instances, "tlas_nodes"_a = u.tlasNodes);
  }

 private:
  int device() const { return runtime_->device().index; }
  // Rays (and times) as device arrays: results into device arrays, on the runtime's stream ordered
  // with `stream` (docs/python.md#device-arrays).
  py::object traceDevice(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle times,
                         py::handle out, std::uintptr_t stream) {
    DeviceArguments args(device(), stream);
    std::vector<py::ssize_t> batch;
    const cuda::GpuRuntime::DeviceRays rays = deviceRays(args, o, d, tmin, tmax, batch);
    const DeviceRayTimes t = deviceRayTimes(args, times, batch);
    static const std::vector<DeviceHitField> kFields = {{"t", "<f4", {"<f4"}},
                                                        {"u", "<f4", {"<f4"}},
                                                        {"v", "<f4", {"<f4"}},
                                                        {"instance", "<i4", {"<i4", "<u4"}},
                                                        {"triangle", "<i4", {"<i4", "<u4"}}};
    std::vector<void*> p;
    const py::dict results = deviceHitArrays(args, out, kFields, batch, device(), p);
    const cuda::GpuTwoLevelRuntime::DeviceHits hits{static_cast<float*>(p[0]), static_cast<float*>(p[1]),
                                                    static_cast<float*>(p[2]), static_cast<uint32_t*>(p[3]),
                                                    static_cast<uint32_t*>(p[4])};
    args.waitForProducers();
    {
      py::gil_scoped_release release;
      const auto handle = reinterpret_cast<cuda::GpuTwoLevelRuntime::StreamHandle>(stream);
      if (t.given)
        runtime_->closestHitsOnDevice(rays, {t.times, t.value}, hits, handle);
      else
        runtime_->closestHitsOnDevice(rays, hits, handle);
    }
    return results;
  }
  py::object occludedDevice(py::handle o, py::handle d, py::handle tmin, py::handle tmax, py::handle times,
                            py::handle out, std::uintptr_t stream) {
    DeviceArguments args(device(), stream);
    std::vector<py::ssize_t> batch;
    const cuda::GpuRuntime::DeviceRays rays = deviceRays(args, o, d, tmin, tmax, batch);
    const DeviceRayTimes t = deviceRayTimes(args, times, batch);
    uint8_t* flags = nullptr;
    const py::object result = deviceFlagArray(args, out, batch, device(), &flags);
    args.waitForProducers();
    {
      py::gil_scoped_release release;
      const auto handle = reinterpret_cast<cuda::GpuTwoLevelRuntime::StreamHandle>(stream);
      if (t.given)
        runtime_->anyHitsOnDevice(rays, {t.times, t.value}, flags, handle);
      else
        runtime_->anyHitsOnDevice(rays, flags, handle);
    }
    return result;
  }

  py::object owner_;  // the tsah.TwoLevelScene scene_ belongs to
  const TwoLevelScene& scene_;
  std::unique_ptr<cuda::GpuTwoLevelRuntime> runtime_;
  cuda::TwoLevelUpdateTimings lastUpdate_;  // zeros until the first update()
};
#endif

namespace {

constexpr const char* kTraceDoc = R"doc(
Closest hits of rays against the scene at the runtime's time. origins, directions: float arrays
(..., 3) of one shape; tmin, tmax: numbers or arrays of the batch shape (...). Returns a numpy
record array of the batch shape with fields t, u, v (float32), instance and triangle (int32: the
instance hit and the triangle id in that instance's source; both -1 and t inf for a miss). out: a
C-contiguous array of that dtype and shape to write into (returned). The GIL is released while
tracing.
)doc";
constexpr const char* kTimesDoc = R"doc(
times: None, or each ray's time in the blurred frame of the last update_shutter, a shutter fraction
(0 the open, 1 the close; outside [0, 1] the nearer end), a number or a float array of the batch
shape. Without a blurred frame (after update) the times change nothing.
)doc";
constexpr const char* kGpuDeviceArraysDoc = R"doc(
Device arrays (docs/python.md#device-arrays): origins and directions given as CUDA arrays
(__cuda_array_interface__ or DLPack: PyTorch, CuPy, JAX), with tmin, tmax and times numbers or
float32 device arrays of the batch shape, are traced in place on the device, ordered after the
work queued on `stream` (None: the legacy default stream; an int or a stream object) and before
the work queued there later; nothing waits. trace then returns a dict of device arrays t, u, v
(float32), instance and triangle (int32; -1 and t inf for a miss), or writes into out= (a dict of
device arrays for some of those keys); occluded a bool device array of the batch shape, or out=
(bool or uint8).
)doc";
constexpr const char* kOccludedDoc =
    "True for each ray that hits anything within (tmin, tmax): a bool array of the batch shape, or written into "
    "out= (bool, C-contiguous).";

}  // namespace

void bindTwoLevel(py::module_& m) {
  const float inf = std::numeric_limits<float>::infinity();
  py::class_<TwoLevelSceneObject>(m, "TwoLevelScene", R"doc(
A scene file kept as two levels (docs/two-level.md): one tree (BLAS) per distinct source, one
top-level tree (TLAS) over the instances, optimized with the T-SAH cost over the scene's frames.
Made by tsah.build_two_level or tsah.load_two_level; traced by tsah.TwoLevelRuntime (and
tsah.GpuTwoLevelRuntime). Pickled as the scene file's absolute path and the .tbvh bytes: unpickling
loads the scene's sources from that path again (the same files must be there) and checks the tree
against them as load_two_level does; auto's structure_choice is not kept.
)doc")
      .def(
          "save",
          [](const TwoLevelSceneObject& s, py::handle path) {
            const std::string file = pathArgument(path, "path");
            py::gil_scoped_release release;
            saveTwoLevelScene(file, s.scene);
          },
          "path"_a, "Writes the two-level .tbvh file (version 3, atomically), what `tsah optimize SCENE` writes.")
      .def_property_readonly(
          "instance_count", [](const TwoLevelSceneObject& s) { return s.scene.instanceCount(); },
          "Number of instances (a flattened object's triangles are one instance).")
      .def_property_readonly(
          "blas_count", [](const TwoLevelSceneObject& s) { return s.scene.blases.size(); },
          "Number of bottom-level trees: one per distinct source.")
      .def_property_readonly(
          "flattened_objects", [](const TwoLevelSceneObject& s) { return flattenedNames(s.scene); },
          "Names of the scene file's objects flattened into one source (list of str; empty when none).")
      .def_property_readonly(
          "start_time", [](const TwoLevelSceneObject& s) { return s.scene.frameTimes.front(); },
          "Time of the scene's first frame.")
      .def_property_readonly(
          "end_time", [](const TwoLevelSceneObject& s) { return s.scene.frameTimes.back(); },
          "Time of the scene's last frame.")
      .def_property_readonly(
          "frame_times", [](const TwoLevelSceneObject& s) { return doubleArray(s.scene.frameTimes); },
          "The scene's frame times (the TLAS's build frames), float64 array.")
      .def_property_readonly("info", &infoDict, R"doc(
The structure as `tsah info TREE SCENE --json` describes it: flattened_objects, instances, poses,
scene_frames, k, ct, ci, max_leaf_size, tlas (nodes, cost, frame_costs), blases (per source: name,
animated, triangles, keyframes, nodes, build_frames, cost), bytes (blas, tlas, total); with
structure="auto", structure_choice (per object: the estimate and the reason).
)doc")
      .def(
          "baked_triangles",
          [](const TwoLevelSceneObject& s, py::handle instances, py::handle triangles) {
            const auto inst = checkedArray<uint32_t>(arrayArgument(instances, "instances", Kind::Integer), "instances",
                                                     Kind::Integer, {-1});
            const auto tri = checkedArray<uint32_t>(arrayArgument(triangles, "triangles", Kind::Integer), "triangles",
                                                    Kind::Integer, {inst.shape(0)});
            py::array_t<int32_t> out(inst.shape(0));
            for (py::ssize_t i = 0; i < inst.shape(0); ++i) {
              if (inst.data()[i] >= s.scene.instanceCount())
                throw tsah::ConfigError("instances: value " + std::to_string(inst.data()[i]) + " (index " +
                                        std::to_string(i) + ") is not an instance");
              if (tri.data()[i] >= s.scene.scene.sourceOf(s.scene.scene.instances[inst.data()[i]]).triangleCount())
                throw tsah::ConfigError("triangles: value " + std::to_string(tri.data()[i]) + " (index " +
                                        std::to_string(i) + ") is not a triangle of instance " +
                                        std::to_string(inst.data()[i]) + "'s source");
              out.mutable_data()[i] = int32_t(s.scene.scene.bakedTriangle(inst.data()[i], tri.data()[i]));
            }
            return out;
          },
          "instances"_a, "triangles"_a,
          "Per (instance, triangle of its source) pair, integer arrays (N,): the triangle's id in tsah.load(scene_path) "
          "(the scene baked into one animation, whatever was flattened), int32 array (N,).")
      // Pickled as the scene file's absolute path and the .tbvh bytes; unpickling loads the scene's
      // sources from that path again and checks the tree against them (load_two_level's checks).
      .def(py::pickle(
          [](const TwoLevelSceneObject& s) {
            std::vector<uint8_t> bytes;
            {
              py::gil_scoped_release release;
              bytes = encodeTwoLevelScene(s.scene);
            }
            return py::make_tuple(s.scenePath, bytesObject(bytes));
          },
          [](const py::tuple& state) {
            if (state.size() != 2 || !py::isinstance<py::str>(state[0]) || !py::isinstance<py::bytes>(state[1]))
              throw tsah::DataError("<pickle>: expected a TwoLevelScene's state (scene path, tree bytes)");
            const std::string path = state[0].cast<std::string>();
            const std::string_view view = state[1].cast<py::bytes>();
            const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(view.data()), view.size());
            std::vector<std::string> warnings;
            TwoLevelScene scene = LongCall().run([&] {
              anim::SceneSources sources = loadSources(path, warnings);  // a missing file stays a FileError
              return inMemory([&] { return decodeTwoLevelScene(bytes, "<pickle>", std::move(sources)); });
            });
            warnAll(warnings);
            return TwoLevelSceneObject{std::move(scene), std::nullopt, path};
          }))
      .def("__repr__", [](const TwoLevelSceneObject& s) {
        return "<tsah.TwoLevelScene: " + std::to_string(s.scene.instanceCount()) + " instances, " +
               std::to_string(s.scene.blases.size()) + " BLAS, " + std::to_string(s.scene.frameTimes.size()) +
               " frames>";
      });

  m.def("load_two_level", &loadTwoLevel, "tree_path"_a, "scene_path"_a, R"doc(
Reads a two-level .tbvh file (version 3) and the scene file it was built for (str or os.PathLike).
Raises tsah.FileError ('FILE: problem') for a file that is no valid two-level tree (a flat tree
included), tsah.DataError ('TREE was not built for SCENE: ...') when the tree does not match the
scene, and the scene's own load errors.
)doc");
  m.def("build_two_level", &buildTwoLevel, "scene_path"_a, "structure"_a = "auto", "k"_a = 0, "frames"_a = 5,
        "selection"_a = "mh", "seed"_a = 1, "ct"_a = 3.0f, "ci"_a = 2.0f, "max_leaf"_a = 8, "time_limit"_a = 0.0,
        "min_improvement"_a = InsertionOptimizer::Config{}.minImprovement, "threads"_a = 0,
        "optimizer"_a = "sequential", "tlas_trees"_a = "auto", "tlas_budget"_a = TlasOptions{}.budget,
        "progress"_a = py::none(), R"doc(
Builds the two-level structure of a scene file as `tsah optimize SCENE --structure STRUCTURE` does:
structure "auto" flattens the objects whose estimated cost is lower flattened (info's
structure_choice; when it flattens every object the scene is one instance of them all, where the
command line writes a flat tree), "two-level" keeps every object instanced. The other arguments
are tsah.optimize's (T-SAH trees: k for animated sources and the TLAS; optimizer "sequential" or
"parallel"). tlas_trees and tlas_budget are the command line's --tlas-trees and --tlas-budget: a
number of top-level trees, each over its part of the scene's time, or "auto". The GIL is released
and Ctrl-C stops the optimizers (KeyboardInterrupt); progress: a callable receiving
{"message": str} events, or None.
)doc");

  py::class_<TwoLevelTracer>(m, "TwoLevelRuntime", R"doc(
TwoLevelRuntime(scene, threads=0, layout="auto", tlas="refit", pose_triangles="vertices"): a
two-level scene traced on the CPU (tsah::TwoLevelRuntime): per update the animated sources' trees
refitted at their local times, the instances' transforms, and the TLAS refitted ("rebuild": rebuilt
per frame, the reference). layout: the BLAS layout, "auto" (the widest this processor's SIMD kernels
support), "bvh2", "bvh4" or "bvh8"; the TLAS is binary. pose_triangles: with bvh4 / bvh8, how the
animated sources' trees hold their triangles: "vertices" (their refit computes no Woop rows) or
"woop" (Woop packets); bvh2 holds Woop triangles. threads: 0 for one per hardware
thread. Starts at the first frame.
)doc")
      .def(py::init([](py::object scene, py::handle threads, const std::string& layout, const std::string& tlas,
                       const std::string& poseTriangles) {
             sceneArgument(scene);  // checked before the other arguments
             return std::make_unique<TwoLevelTracer>(std::move(scene), checkedInteger<unsigned>(threads, "threads"),
                                                     layout, tlas, poseTriangles);
           }),
           "scene"_a, "threads"_a = 0, "layout"_a = "auto", "tlas"_a = "refit", "pose_triangles"_a = "vertices")
      .def("update", &TwoLevelTracer::update, "time"_a,
           "The scene at this time (a float; clamped to the scene's range); ends a blurred frame.")
      .def("update_shutter", &TwoLevelTracer::updateShutter, "open"_a, "close"_a, R"doc(
A blurred frame over the shutter [open, close] (scene times, open <= close; docs/motion-blur.md):
trace and occluded then take each ray's time (times=). One instant (open == close) or a shutter in
which nothing moves is update(open): not blurred.
)doc")
      .def("trace", &TwoLevelTracer::trace, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "times"_a = py::none(), "out"_a = py::none(), (std::string(kTraceDoc) + kTimesDoc).c_str())
      .def("occluded", &TwoLevelTracer::occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "times"_a = py::none(), "out"_a = py::none(), (std::string(kOccludedDoc) + kTimesDoc).c_str())
      .def_property_readonly(
          "time", [](const TwoLevelTracer& r) { return r.runtime().time(); },
          "The scene time of the last update (of a blurred frame: its close).")
      .def_property_readonly(
          "blurred", [](const TwoLevelTracer& r) { return r.runtime().blurred(); },
          "True after an update_shutter that made a blurred frame (until update).")
      .def_property_readonly(
          "instance_boxes", [](const TwoLevelTracer& r) { return boxesArray(r.runtime().instanceBoxes()); },
          "The instances' world boxes at the current time (of a blurred frame: its close), float32 (I, 2, 3): "
          "minimum then maximum.")
      .def_property_readonly(
          "memory_bytes", [](const TwoLevelTracer& r) { return r.runtime().memoryBytes(); },
          "Bytes the runtime holds: every BLAS runtime's tree, triangles and positions, the TLAS, the instances.");

#if defined(TSAH_HAVE_CUDA)
  py::class_<GpuTwoLevelTracer>(m, "GpuTwoLevelRuntime", R"doc(
GpuTwoLevelRuntime(scene, device=0, layout="auto", tlas="refit"): the same on a CUDA device
(tsah::cuda::GpuTwoLevelRuntime), tracing host (numpy) rays or device arrays in place. layout: the
BLAS layout, "auto" (bvh2), "bvh2" or "cwbvh" (compressed 8-wide nodes); the TLAS is binary.
tlas: "refit" (the T-SAH TLAS refitted), "lbvh" or "hlbvh-sah" (rebuilt on the GPU every update). Motion blur as
TwoLevelRuntime's (update_shutter, times=; the blurred frame refits the T-SAH TLAS at every key
whatever tlas). Raises tsah.Failure when no device is usable.
)doc")
      .def(py::init([](py::object scene, py::handle device, const std::string& layout, const std::string& tlas) {
             sceneArgument(scene);
             return std::make_unique<GpuTwoLevelTracer>(std::move(scene), checkedInteger<int>(device, "device", 0),
                                                        layout, tlas);
           }),
           "scene"_a, "device"_a = 0, "layout"_a = "auto", "tlas"_a = "refit")
      .def("update", &GpuTwoLevelTracer::update, "time"_a, "The scene at this time, on the device; ends a blurred frame.")
      .def("update_shutter", &GpuTwoLevelTracer::updateShutter, "open"_a, "close"_a,
           "A blurred frame over the shutter [open, close] on the device, as TwoLevelRuntime.update_shutter.")
      .def("trace", &GpuTwoLevelTracer::trace, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "times"_a = py::none(), "out"_a = py::none(), py::kw_only(), "stream"_a = py::none(),
           (std::string(kTraceDoc) + kTimesDoc + kGpuDeviceArraysDoc).c_str())
      .def("occluded", &GpuTwoLevelTracer::occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = inf,
           "times"_a = py::none(), "out"_a = py::none(), py::kw_only(), "stream"_a = py::none(),
           (std::string(kOccludedDoc) + kTimesDoc + kGpuDeviceArraysDoc).c_str())
      .def_property_readonly("time", &GpuTwoLevelTracer::time,
                             "The scene time of the last update (of a blurred frame: its close).")
      .def_property_readonly("blurred", &GpuTwoLevelTracer::blurred,
                             "True after an update_shutter that made a blurred frame (until update).")
      .def_property_readonly("device_name", &GpuTwoLevelTracer::deviceName, "The name of the GPU the runtime uses.")
      .def_property_readonly("last_update", &GpuTwoLevelTracer::lastUpdate,
                             "Device time of the last update (ms): upload_ms, blas_ms, tlas_ms, tlas_rebuild_ms, "
                             "total_ms; blas_refits, instances, tlas_nodes (zeros before the first update).");
#endif
}

}  // namespace tsah::python
