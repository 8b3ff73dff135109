#pragma once
// The pieces of the tsah Python module (one translation unit each) and the numpy checks they share.
// Every function here only converts between numpy/Python and the C++ API; none computes anything
// the libraries compute.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <limits>
#include <string>
#include <type_traits>
#include <typeinfo>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/io/tree_set.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"
#include "tsah/optimize/segmentation.hpp"
#include "tsah/pipeline.hpp"

namespace anim {
class Animation;
}
namespace tsah {
struct OptimizedTreeSet;
}

namespace tsah {
class CpuRuntime;
namespace cuda {
class GpuRuntime;
}
}  // namespace tsah

namespace tsah::python {

namespace py = pybind11;

// A tree as the module hands it out: the Bvh and its .tbvh header, plus the optimizer's record
// when the tree was built in this process.
struct Tree {
  BvhFile file;
  bool optimized = false;
  InsertionOptimizer::Result optimization;
};

// A tree set as the module hands it out (tsah.TreeSet, trees.cpp): the decoded set that the
// runtimes take (tsah::CpuRuntime / GpuRuntime accept `set`), the bytes of its .tbvh file (what
// save, to_bytes and pickling write), and for a set built in this process the search's record.
struct TreeSetObject {
  tsah::TreeSet set;
  std::vector<uint8_t> bytes;
  bool optimized = false;
  SegmentationResult search;  // when optimized: parts, costs, budget (its trees moved out)
};

class CpuTracer;  // tsah.CpuRuntime (runtime.cpp)
class GpuTracer;  // tsah.GpuRuntime (runtime.cpp, CUDA builds)
class DeviceArray;  // tsah.DeviceArray (device_array_type.cpp, CUDA builds)
struct TwoLevelSceneObject;  // tsah.TwoLevelScene (two_level.cpp)
class TwoLevelTracer;  // tsah.TwoLevelRuntime (two_level.cpp)
class GpuTwoLevelTracer;  // tsah.GpuTwoLevelRuntime (two_level.cpp, CUDA builds)
// The C++ runtime of a tsah.CpuRuntime / tsah.GpuRuntime object (checked as every bound argument).
const CpuRuntime& cpuRuntimeOf(py::handle self);
// A CPU runtime's layout argument: "auto" (the widest the processor's SIMD kernels support),
// "bvh2", "bvh4" or "bvh8"; cwbvh is refused as a GPU layout (runtime.cpp).
Layout cpuLayoutArgument(const std::string& layout);
// A GPU runtime's: "auto" (the binary layout, tsah::gpuLayout), "bvh2" or "cwbvh"; the CPU's wide
// layouts are refused (runtime.cpp).
Layout gpuLayoutArgument(const std::string& layout);
// A wide CPU layout's triangle form argument, "woop" or "vertices"; anything else is refused as
// "ARGUMENT: unknown triangle form ..." (runtime.cpp).
TriangleForm triangleFormArgument(const std::string& form, const char* argument);
#if defined(TSAH_HAVE_CUDA)
cuda::GpuRuntime& gpuRuntimeOf(py::handle self);
#endif

// The C++ classes bound as Python classes. Each is loaded through the type_caster below, so an
// object made by Class.__new__ without __init__ is refused wherever it is passed, `self` included;
// python/tests/test_construction.py fails for a class bound without an entry here.
template <class T>
struct IsBoundClass
    : std::bool_constant<std::is_same_v<T, anim::Animation> || std::is_same_v<T, Tree> ||
                         std::is_same_v<T, TreeSetObject> || std::is_same_v<T, CpuTracer> ||
                         std::is_same_v<T, GpuTracer> || std::is_same_v<T, DeviceArray> ||
                         std::is_same_v<T, TwoLevelSceneObject> || std::is_same_v<T, TwoLevelTracer> ||
                         std::is_same_v<T, GpuTwoLevelTracer>> {};

// Throws tsah::ConfigError when `obj` is an instance of the Python class bound to `type` whose C++
// object was never constructed (Class.__new__(Class) without __init__). pybind11 itself would hand
// the method freshly allocated, uninitialised memory of the class's size.
void requireConstructed(py::handle obj, const std::type_info& type);

// A Python argument of the wrong type or dtype: a tsah::ConfigError that Python sees as
// tsah.ArgumentTypeError, a subclass of tsah.ConfigError and of TypeError (module.cpp).
class ArgumentTypeError : public tsah::ConfigError {
 public:
  using tsah::ConfigError::ConfigError;
};

// Runs a long C++ call so that Ctrl-C stops it, with progress reported to Python:
//
//   LongCall call(progress);                       // a Python callable or None
//   options.cancelled = call.cancelled();          // TreeOptions / InsertionOptimizer::Config
//   options.batchProgress = [&call](const auto& r) { call.report([r] { return py::dict(...); }); };
//   Result result = call.run([&] { return longWork(options); });
//
// run() is called with the GIL held. The work runs on a worker thread; the calling thread releases
// the GIL and wakes every 50 ms (and at every report) to take the GIL, call the progress callback
// with each queued event, and run Python's signal handlers (PyErr_CheckSignals). When a handler
// raises (KeyboardInterrupt for Ctrl-C) or the callback raises, the cancel flag is set, run() waits
// for the work to return, and raises that Python exception. Cancellation is cooperative: the work
// must poll cancelled() (the optimizers do, through their configs, within 32 steps or a round) and
// throw tsah::Cancelled, or Ctrl-C acts only when the work ends. A tsah::Cancelled that reaches the
// exception translator becomes KeyboardInterrupt. Per-thread state of the C++ side (the CUDA
// device chosen with cudaSetDevice) must be set inside the work, which runs on another thread.
class LongCall {
 public:
  explicit LongCall(py::object progress = py::none());
  ~LongCall();
  LongCall(const LongCall&) = delete;
  LongCall& operator=(const LongCall&) = delete;

  // The cancel check to hand to the C++ side: cheap, thread-safe, true once the call is cancelled.
  std::function<bool()> cancelled() const;
  // Queues a progress event from any thread; `event` is called on the calling thread with the GIL
  // held and its result passed to the progress callback. Nothing happens without a callback.
  void report(std::function<py::object()> event);
  bool reports() const;  // whether there is a callback to report to

  template <class Work>
  auto run(Work work) -> std::invoke_result_t<Work> {
    using Result = std::invoke_result_t<Work>;
    if constexpr (std::is_void_v<Result>) {
      runErased([&work] { work(); });
    } else {
      std::optional<Result> out;
      runErased([&work, &out] { out.emplace(work()); });
      return std::move(*out);
    }
  }

 private:
  void runErased(const std::function<void()>& work);
  struct State;
  std::unique_ptr<State> state_;
};

// A path argument: str or any os.PathLike (pathlib.Path), through os.fspath; ArgumentTypeError
// naming `name` otherwise (bytes paths included).
std::string pathArgument(py::handle path, const char* name);

// The command line's tree options as keyword arguments, checked as the command line checks them
// (trees.cpp: tsah.optimize's arguments of the same names).
TreeOptions treeOptions(const std::string& method, py::handle k, py::handle frames, const std::string& selection,
                        py::handle seed, float ct, float ci, py::handle maxLeaf, double timeLimit,
                        double minImprovement, py::handle threads, const std::string& optimizer);
// Hooks `call` into the options: its cancel check, and (with a callback) progress messages or, with
// `batches`, the optimizer's batch records.
void connect(TreeOptions& options, LongCall& call, bool batches);

// Creates tsah.Error, ConfigError, DataError, FileError, Failure and ArgumentTypeError in `m` and
// translates the C++ exceptions to them (tsah::Cancelled to KeyboardInterrupt).
void bindErrors(py::module_& m);
void bindAnimation(py::module_& m);
void bindTrees(py::module_& m);
void bindRuntimes(py::module_& m);
void bindQueries(py::module_& m);  // after bindRuntimes: adds methods to its classes (queries.cpp)
void bindTreeSets(py::module_& m);  // tsah.TreeSet (tree_sets.cpp), called by bindTrees
void bindTwoLevel(py::module_& m);  // two-level scenes and their runtimes (two_level.cpp)

// A tree set for Python from a set file's bytes and their decoded set (read_tree, tree_from_bytes),
// or from a set built in this process (optimize with segments).
TreeSetObject treeSetFromBytes(std::vector<uint8_t> bytes, tsah::TreeSet decoded);
TreeSetObject treeSetFromOptimized(OptimizedTreeSet built);

// decode() of bytes handed over in memory: they are data, not a file, so the decoder's
// tsah::FileError ("NAME: problem") becomes a tsah::DataError with the same message.
template <class Decode>
auto inMemory(Decode decode) -> std::invoke_result_t<Decode> {
  try {
    return decode();
  } catch (const tsah::FileError& e) {
    throw tsah::DataError(e.what());
  }
}

// Copies as Python objects: a float64 array, bytes.
py::array_t<double> doubleArray(const std::vector<double>& values);
py::bytes bytesObject(std::span<const uint8_t> bytes);

// A C-contiguous numpy array of T (converted from the caller's dtype when needed).
template <class T>
using Array = py::array_t<T, py::array::c_style | py::array::forcecast>;

// Which dtypes an argument takes: floating point, integers, or both.
enum class Kind { Float, Integer, Number };

// `obj` as a C-contiguous numpy array of T after checking it: ArgumentTypeError (Python: a TypeError)
// unless it is a numpy array of the right kind of dtype, tsah::ConfigError (a ValueError) unless its
// shape is `shape` (-1: any size). For integer targets every value must fit T (ConfigError naming
// the first one that does not).
template <class T>
Array<T> checkedArray(py::handle obj, const std::string& name, Kind kind,
                                                std::initializer_list<py::ssize_t> shape);

// A numeric argument given as a Python sequence (list, tuple) or a numpy scalar: as a numpy array
// (np.asarray; float64 for a Float argument) for checkedArray; anything else unchanged
// (checkedArray judges it). ArgumentTypeError naming `name` for a ragged or non-numeric sequence.
py::object arrayArgument(py::handle value, const char* name, Kind kind);

// `value`, a Python int (or a numpy integer), as T: ArgumentTypeError unless it is one, tsah::ConfigError naming `name`
// unless it is in [lo, hi] (so -1 is refused instead of pybind11's "incompatible arguments").
template <class T>
T checkedInteger(py::handle value, const char* name, T lo = std::numeric_limits<T>::min(),
                 T hi = std::numeric_limits<T>::max());

// `t` unless it is NaN or infinite (tsah::ConfigError naming `name`).
double checkedTime(double t, const char* name);

// The shape of `a` as text, e.g. "(4, 3)".
std::string shapeText(const py::array& a);
std::string shapeText(const std::vector<py::ssize_t>& shape);

}  // namespace tsah::python

namespace pybind11::detail {

// pybind11's caster for the bound classes, with requireConstructed before the object is used.
template <class T>
class type_caster<T, enable_if_t<tsah::python::IsBoundClass<T>::value>> : public type_caster_base<T> {
 public:
  bool load(handle src, bool convert) {
    tsah::python::requireConstructed(src, typeid(T));
    return type_caster_base<T>::load(src, convert);
  }
};

}  // namespace pybind11::detail
