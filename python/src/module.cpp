// The tsah Python module: errors, animations (load, generate, build from numpy arrays, save), and
// the parts bound in trees.cpp and runtime.cpp.
#include <pybind11/stl.h>

#include "tsah/base/error.hpp"
#include "anim/generators.hpp"
#include "anim/load.hpp"
#include "anim/tanim.hpp"
#include "bindings.hpp"
#include "device_arrays.hpp"

namespace tsah::python {

namespace {

using namespace pybind11::literals;

// A copy of `values` as a float32 array of the given shape.
py::array_t<float> floatArray(std::span<const float> values, std::vector<py::ssize_t> shape) {
  py::array_t<float> out(std::move(shape));
  std::copy(values.begin(), values.end(), out.mutable_data());
  return out;
}

anim::Animation makeAnimation(py::handle trianglesArg, py::handle positionsArg, py::handle timesArg,
                              const std::string& name) {
  const py::object triangles = arrayArgument(trianglesArg, "triangles", Kind::Integer),
                   positions = arrayArgument(positionsArg, "positions", Kind::Float),
                   times = arrayArgument(timesArg, "times", Kind::Number);
  const auto tri = checkedArray<uint32_t>(triangles, "triangles", Kind::Integer, {-1, 3});
  const py::array posArray = py::isinstance<py::array>(positions) ? py::reinterpret_borrow<py::array>(positions) : py::array();
  // One frame may be given as (V, 3); otherwise (F, V, 3).
  const bool oneFrame = posArray && posArray.ndim() == 2;
  const auto pos = oneFrame ? checkedArray<float>(positions, "positions", Kind::Float, {-1, 3})
                            : checkedArray<float>(positions, "positions", Kind::Float, {-1, -1, 3});
  const py::ssize_t frames = oneFrame ? 1 : pos.shape(0);
  const py::ssize_t vertices = oneFrame ? pos.shape(0) : pos.shape(1);
  std::vector<double> keyTimes;
  if (times.is_none()) {
    for (py::ssize_t f = 0; f < frames; ++f) keyTimes.push_back(double(f));
  } else {
    const auto t = checkedArray<double>(times, "times", Kind::Number, {-1});
    if (t.shape(0) != frames)
      throw tsah::ConfigError("times: expected " + std::to_string(frames) + " times (one per frame), got " +
                              std::to_string(t.shape(0)));
    keyTimes.assign(t.data(), t.data() + t.size());
  }
  if (vertices > py::ssize_t(UINT32_MAX)) throw tsah::DataError("positions: too many vertices");
  return anim::Animation(std::vector<uint32_t>(tri.data(), tri.data() + tri.size()), uint32_t(vertices),
                         std::vector<float>(pos.data(), pos.data() + pos.size()), std::move(keyTimes), name);
}

anim::Animation loadAnimation(py::handle pathArg, double fps, const std::string& clip) {
  const std::string path = pathArgument(pathArg, "path");
  anim::LoadOptions options;
  options.fps = fps;
  options.clip = clip;
  std::vector<std::string> warnings;
  options.warning = [&warnings](const std::string& w) { warnings.push_back(w); };
  // The importers take no cancel check: Ctrl-C is raised when the load returns.
  anim::Animation a = LongCall().run([&] { return anim::load(path, options); });
  for (const std::string& w : warnings) PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1);
  return a;
}

py::array_t<float> boundsArray(const anim::Bounds& b) {
  py::array_t<float> out(std::vector<py::ssize_t>{2, 3});
  for (int a = 0; a < 3; ++a) {
    out.mutable_at(0, a) = b.min[std::size_t(a)];
    out.mutable_at(1, a) = b.max[std::size_t(a)];
  }
  return out;
}

// The Python classes of the C++ exceptions (tsah/base/error.hpp), created once at import and kept
// for the life of the process (the translator below needs them after the module object is gone).
struct ErrorClasses {
  PyObject* error = nullptr;
  PyObject* config = nullptr;
  PyObject* data = nullptr;
  PyObject* file = nullptr;
  PyObject* failure = nullptr;
  PyObject* argumentType = nullptr;
};
ErrorClasses errorClasses;

// A new exception class tsah.<name> with the given bases, added to `m`.
PyObject* newErrorClass(py::module_& m, const char* name, const char* doc, std::initializer_list<PyObject*> bases) {
  py::tuple baseTuple(bases.size());
  std::size_t i = 0;
  for (PyObject* base : bases) baseTuple[i++] = py::handle(base);
  const std::string fullName = std::string("tsah.") + name;
  PyObject* cls = PyErr_NewExceptionWithDoc(fullName.c_str(), doc, baseTuple.ptr(), nullptr);
  if (!cls) throw py::error_already_set();
  m.add_object(name, py::handle(cls));  // the module takes its own reference; ours is never released
  return cls;
}

}  // namespace

std::string pathArgument(py::handle path, const char* name) {
  if (!py::isinstance<py::str>(path) && !py::hasattr(path, "__fspath__"))
    throw ArgumentTypeError(std::string(name) + ": expected a str or os.PathLike path, got " +
                            std::string(py::str(path.get_type().attr("__name__"))));
  const py::object text = py::module_::import("os").attr("fspath")(path);
  if (!py::isinstance<py::str>(text))
    throw ArgumentTypeError(std::string(name) + ": expected a str path, got " +
                            std::string(py::str(text.get_type().attr("__name__"))));
  return text.cast<std::string>();
}

py::object arrayArgument(py::handle value, const char* name, Kind kind) {
  const py::module_ numpy = py::module_::import("numpy");
  const bool sequence = py::isinstance<py::list>(value) || py::isinstance<py::tuple>(value);
  if (!sequence && !py::isinstance(value, numpy.attr("generic"))) return py::reinterpret_borrow<py::object>(value);
  try {
    // Numbers in a list have no dtype: a float target takes ints as floats.
    return kind == Kind::Float ? numpy.attr("asarray")(value, "dtype"_a = "float64") : numpy.attr("asarray")(value);
  } catch (py::error_already_set&) {  // ragged or not numbers
    throw ArgumentTypeError(std::string(name) + ": expected numbers in a rectangular sequence");
  }
}

void bindErrors(py::module_& m) {
  ErrorClasses& c = errorClasses;
  c.error = newErrorClass(m, "Error",
                          "An error of the toolkit, with its one-line message ('FILE: problem'). The base of\n"
                          "ConfigError, DataError (FileError) and Failure; a RuntimeError.",
                          {PyExc_RuntimeError});
  c.config = newErrorClass(m, "ConfigError",
                           "An invalid request: an option or argument out of range, an unknown name, settings that\n"
                           "contradict each other, a call the object cannot serve (a tsah.Error and a ValueError).",
                           {c.error, PyExc_ValueError});
  c.data = newErrorClass(m, "DataError",
                         "Unusable data: NaN coordinates, a tree that is not a tree, a tree built for another\n"
                         "animation (a tsah.Error and a ValueError).",
                         {c.error, PyExc_ValueError});
  c.file = newErrorClass(m, "FileError",
                         "An input or tree file that cannot be read; the message starts with the file name (a\n"
                         "tsah.DataError).",
                         {c.data});
  c.failure = newErrorClass(m, "Failure",
                            "The request and the data were fine but the work failed: a write error, a full disk,\n"
                            "not enough memory, a GPU error (a tsah.Error, so a RuntimeError).",
                            {c.error});
  c.argumentType = newErrorClass(m, "ArgumentTypeError",
                                 "An argument of the wrong type or dtype (a tsah.ConfigError and a TypeError).",
                                 {c.config, PyExc_TypeError});
  // One translator, the most specific class first (pybind11 tries translators latest-registered
  // first; anything that is not a tsah::Error falls through to pybind11's own).
  py::register_exception_translator([](std::exception_ptr p) {
    const ErrorClasses& classes = errorClasses;
    try {
      if (p) std::rethrow_exception(p);
    } catch (const tsah::Cancelled&) {
      PyErr_SetNone(PyExc_KeyboardInterrupt);  // what Python's Ctrl-C raises; nothing was produced
    } catch (const ArgumentTypeError& e) {
      PyErr_SetString(classes.argumentType, e.what());
    } catch (const tsah::FileError& e) {
      PyErr_SetString(classes.file, e.what());
    } catch (const tsah::DataError& e) {
      PyErr_SetString(classes.data, e.what());
    } catch (const tsah::ConfigError& e) {
      PyErr_SetString(classes.config, e.what());
    } catch (const tsah::Failure& e) {
      PyErr_SetString(classes.failure, e.what());
    } catch (const tsah::Error& e) {
      PyErr_SetString(classes.error, e.what());
    }
  });
}

void bindAnimation(py::module_& m) {
  py::class_<anim::Animation>(m, "Animation", R"doc(
An animated triangle mesh: one triangle list for all frames, vertex positions per keyframe, and the
keyframe times. Positions between keyframes are interpolated linearly (clamped at the ends).

Animation(triangles, positions, times=None, name="")
  triangles  integer array (T, 3): vertex indices of each triangle
  positions  float array (F, V, 3): positions of the V vertices in each of F keyframes, or (V, 3) for one frame
  times      numbers (F,): strictly increasing keyframe times (default 0, 1, ..., F-1)
Raises tsah.ArgumentTypeError (a TypeError) for a wrong dtype, tsah.ConfigError (a ValueError) for a
wrong shape, tsah.DataError (its subclass tsah.FileError, naming the animation) for inconsistent
data (an index out of range, times not increasing, NaN or infinite coordinates).
)doc")
      .def(py::init(&makeAnimation), "triangles"_a, "positions"_a, "times"_a = py::none(), "name"_a = "")
      .def_property_readonly("name", &anim::Animation::name, "Name of the input (file stem) or the given name.")
      .def_property_readonly("triangle_count", &anim::Animation::triangleCount, "Number of triangles.")
      .def_property_readonly("vertex_count", &anim::Animation::vertexCount, "Number of vertices.")
      .def_property_readonly("keyframe_count", &anim::Animation::keyframeCount, "Number of keyframes.")
      .def_property_readonly("start_time", &anim::Animation::startTime, "Time of the first keyframe.")
      .def_property_readonly("end_time", &anim::Animation::endTime, "Time of the last keyframe.")
      .def_property_readonly(
          "triangles",
          [](const anim::Animation& a) {
            py::array_t<uint32_t> out(std::vector<py::ssize_t>{py::ssize_t(a.triangleCount()), 3});
            std::copy(a.indices().begin(), a.indices().end(), out.mutable_data());
            return out;
          },
          "Vertex indices, uint32 array (T, 3) (a copy).")
      .def_property_readonly(
          "positions",
          [](const anim::Animation& a) {
            return floatArray(a.allPositions(), {a.keyframeCount(), a.vertexCount(), 3});
          },
          "Keyframe positions, float32 array (F, V, 3) (a copy).")
      .def_property_readonly(
          "times", [](const anim::Animation& a) { return py::array_t<double>(py::ssize_t(a.times().size()), a.times().data()); },
          "Keyframe times, float64 array (F,).")
      .def_property_readonly(
          "bounds", [](const anim::Animation& a) { return boundsArray(a.bounds()); },
          "Bounds over every keyframe: float32 array (2, 3), minimum then maximum.")
      .def(
          "positions_at",
          [](const anim::Animation& a, double t) {
            return floatArray(a.positionsAt(checkedTime(t, "t")), {a.vertexCount(), 3});
          },
          "t"_a, "Vertex positions at time t, float32 array (V, 3) (linear between keyframes, clamped).")
      .def(
          "uniform_times",
          [](const anim::Animation& a, py::handle n) {
            const std::vector<double> t =
                a.uniformTimes(checkedInteger<uint32_t>(n, "n", 1, anim::Animation::kMaxResampleFrames));
            return py::array_t<double>(py::ssize_t(t.size()), t.data());
          },
          "n"_a, "n times spread uniformly over [start_time, end_time], both ends included.")
      .def(
          "resample",
          [](const anim::Animation& a, py::handle n) {
            return a.resample(checkedInteger<uint32_t>(n, "n", 1, anim::Animation::kMaxResampleFrames));
          },
          "n"_a,
           "A new animation with n keyframes at uniform_times(n) (what `tsah resample --frames n` writes).")
      .def(
          "segment",
          [](const anim::Animation& a, double t0, double t1) {
            return a.segment(checkedTime(t0, "t0"), checkedTime(t1, "t1"));
          },
          "t0"_a, "t1"_a,
           "The part between t0 and t1: keyframes at t0, t1 and every original keyframe between them.")
      .def(
          "save",
          [](const anim::Animation& a, py::handle path) { anim::saveTanim(a, pathArgument(path, "path")); }, "path"_a,
          "Writes the animation as a .tanim file (atomically), as `tsah resample` does.")
      .def("__repr__", [](const anim::Animation& a) {
        return "<tsah.Animation '" + a.name() + "': " + std::to_string(a.triangleCount()) + " triangles, " +
               std::to_string(a.vertexCount()) + " vertices, " + std::to_string(a.keyframeCount()) + " keyframes>";
      });

  m.def("load", &loadAnimation, "path"_a, "fps"_a = 0.0, "clip"_a = "", R"doc(
Loads any input the command line reads: a .tanim file, a BART .aff scene, an animated model (MD2,
glTF/GLB, FBX, Collada; baked at fps), a mesh file (OBJ, PLY, OFF, STL, OM), a directory of mesh
files, a printf pattern ('frames/walk_%04d.obj'), a glob ('frames/*.obj') or a JSON manifest.
Importer warnings become Python UserWarnings. Raises tsah.FileError with the command line's one-line
message ('FILE: problem') when the input cannot be read.
)doc");

  m.def(
      "generate",
      [](const std::string& kind, py::handle triangles, py::handle frames, py::handle seed) {
        anim::GeneratorOptions options;
        options.triangles = checkedInteger<uint32_t>(triangles, "triangles");
        options.frames = checkedInteger<uint32_t>(frames, "frames");
        options.seed = checkedInteger<uint64_t>(seed, "seed");
        return anim::generate(anim::parseGeneratorKind(kind), options);
      },
      "kind"_a, "triangles"_a = 4000, "frames"_a = 30, "seed"_a = 1,
      "A procedural animation ('explode', 'wave' or 'swap'), as `tsah generate` makes it.");
}

}  // namespace tsah::python

PYBIND11_MODULE(_tsah, m) {
  namespace py = pybind11;
  m.doc() = "T-SAH: one BVH optimized for every frame of an animation (the C++ toolkit's Python layer).";
  m.attr("__version__") = TSAH_VERSION;
  tsah::python::bindErrors(m);
  tsah::python::bindAnimation(m);
  tsah::python::bindTrees(m);
  tsah::python::bindRuntimes(m);
  tsah::python::bindQueries(m);
  tsah::python::bindTwoLevel(m);
  tsah::python::bindDeviceArrays(m);
}
