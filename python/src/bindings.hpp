#pragma once
// The pieces of the tsah Python module (one translation unit each) and the numpy checks they share.
// Every function here only converts between numpy/Python and the C++ API; none computes anything
// the libraries compute.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"
#include "tsah/core/bvh.hpp"
#include "tsah/io/bvh_file.hpp"
#include "tsah/optimize/insertion_optimizer.hpp"

namespace tsah::python {

namespace py = pybind11;

// A tree as the module hands it out: the Bvh and its .tbvh header, plus the optimizer's record
// when the tree was built in this process.
struct Tree {
  BvhFile file;
  bool optimized = false;
  InsertionOptimizer::Result optimization;
};

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

// The shape of `a` as text, e.g. "(4, 3)".
std::string shapeText(const py::array& a);

}  // namespace tsah::python
