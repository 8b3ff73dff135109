#pragma once
// The pieces of the tsah Python module (one translation unit each) and the numpy checks they share.
// Every function here only converts between numpy/Python and the C++ API; none computes anything
// the libraries compute.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <typeinfo>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"

namespace anim {
class Animation;
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

class CpuTracer;  // tsah.CpuRuntime (runtime.cpp)
class GpuTracer;  // tsah.GpuRuntime (runtime.cpp, CUDA builds)
// The C++ runtime of a tsah.CpuRuntime / tsah.GpuRuntime object (checked as every bound argument).
const CpuRuntime& cpuRuntimeOf(py::handle self);
#if defined(TSAH_HAVE_CUDA)
cuda::GpuRuntime& gpuRuntimeOf(py::handle self);
#endif

// The C++ classes bound as Python classes. Each is loaded through the type_caster below, so an
// object made by Class.__new__ without __init__ is refused wherever it is passed, `self` included;
// python/tests/test_construction.py fails for a class bound without an entry here.
template <class T>
struct IsBoundClass
    : std::bool_constant<std::is_same_v<T, anim::Animation> || std::is_same_v<T, Tree> ||
                         std::is_same_v<T, CpuTracer> || std::is_same_v<T, GpuTracer>> {};

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

// Creates tsah.Error, ConfigError, DataError, FileError, Failure and ArgumentTypeError in `m` and
// translates the C++ exceptions to them.
void bindErrors(py::module_& m);
void bindAnimation(py::module_& m);
void bindTrees(py::module_& m);
void bindRuntimes(py::module_& m);
void bindQueries(py::module_& m);  // after bindRuntimes: adds methods to its classes (queries.cpp)

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

// `value`, a Python int, as T: ArgumentTypeError unless it is an int, tsah::ConfigError naming `name`
// unless it is in [lo, hi] (so -1 is refused instead of pybind11's "incompatible arguments").
template <class T>
T checkedInteger(py::handle value, const char* name, T lo = std::numeric_limits<T>::min(),
                 T hi = std::numeric_limits<T>::max());

// `t` unless it is NaN or infinite (tsah::ConfigError naming `name`).
double checkedTime(double t, const char* name);

// The shape of `a` as text, e.g. "(4, 3)".
std::string shapeText(const py::array& a);

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
