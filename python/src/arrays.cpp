// Argument checks of the Python module: bound objects must have been constructed, integers must fit
// their C++ type, times must be finite; for numpy arguments, wrong types raise
// tsah.ArgumentTypeError (a TypeError), wrong shapes or values tsah.ConfigError (a ValueError), always
// with the argument's name, before any data reaches the C++ API.
#include <cfloat>
#include <cmath>
#include <limits>

#include "bindings.hpp"
#include "device_arrays.hpp"
#include "tsah/base/error.hpp"

namespace tsah::python {

void requireConstructed(py::handle obj, const std::type_info& type) {
  const py::detail::type_info* bound = py::detail::get_type_info(type);
  // Not an instance of this class: pybind11's own load refuses it.
  if (!bound || !obj || !PyObject_TypeCheck(obj.ptr(), bound->type)) return;
  auto* instance = reinterpret_cast<py::detail::instance*>(obj.ptr());
  if (instance->get_value_and_holder(bound).holder_constructed()) return;
  const std::string name = py::str(py::handle(reinterpret_cast<PyObject*>(bound->type)).attr("__name__"));
  throw tsah::ConfigError("tsah." + name + " is not initialised (made by " + name +
                          ".__new__ without __init__): call tsah." + name + "(...)");
}

template <class T>
T checkedInteger(py::handle arg, const char* name, T lo, T hi) {
  // An int or anything with __index__ (numpy integer scalars); never a bool (numpy's neither).
  const bool isBool = py::isinstance<py::bool_>(arg) || py::isinstance(arg, py::module_::import("numpy").attr("bool_"));
  if (isBool || !PyIndex_Check(arg.ptr()))
    throw ArgumentTypeError(std::string(name) + ": expected an int, got " +
                            std::string(py::str(arg.get_type().attr("__name__"))));
  const auto value = py::reinterpret_steal<py::int_>(PyNumber_Index(arg.ptr()));
  if (!value) throw py::error_already_set();
  const py::int_ low(lo), high(hi);
  if (value < low || value > high)
    throw tsah::ConfigError(std::string(name) + ": must be in " + std::to_string(lo) + ".." + std::to_string(hi) +
                            ", not " + std::string(py::str(py::handle(value))));
  return value.cast<T>();
}

template uint64_t checkedInteger<uint64_t>(py::handle, const char*, uint64_t, uint64_t);
template uint32_t checkedInteger<uint32_t>(py::handle, const char*, uint32_t, uint32_t);
template int checkedInteger<int>(py::handle, const char*, int, int);
template long checkedInteger<long>(py::handle, const char*, long, long);

double checkedTime(double t, const char* name) {
  if (!std::isfinite(t))
    throw tsah::ConfigError(std::string(name) + ": must be a finite time, not " + std::string(py::str(py::float_(t))));
  return t;
}

std::string shapeText(const std::vector<py::ssize_t>& shape) {
  std::string text = "(";
  for (std::size_t d = 0; d < shape.size(); ++d) text += (d ? ", " : "") + std::to_string(shape[d]);
  return text + (shape.size() == 1 ? ",)" : ")");
}

std::string shapeText(const py::array& a) { return shapeText(std::vector<py::ssize_t>(a.shape(), a.shape() + a.ndim())); }

namespace {

std::string expectedShape(std::initializer_list<py::ssize_t> shape) {
  std::string text = "(";
  std::size_t i = 0;
  for (py::ssize_t d : shape) text += (i++ ? ", " : "") + (d < 0 ? std::string("N") : std::to_string(d));
  return text + (shape.size() == 1 ? ",)" : ")");
}

bool kindAccepts(Kind kind, char dtypeKind) {
  const bool isFloat = dtypeKind == 'f';
  const bool isInteger = dtypeKind == 'i' || dtypeKind == 'u';
  switch (kind) {
    case Kind::Float: return isFloat;
    case Kind::Integer: return isInteger;
    case Kind::Number: return isFloat || isInteger;
  }
  return false;
}

const char* kindName(Kind kind) {
  switch (kind) {
    case Kind::Float: return "a floating-point";
    case Kind::Integer: return "an integer";
    case Kind::Number: return "a numeric";
  }
  return "a";
}

// Device-memory arrays (CUDA's __cuda_array_interface__, or __dlpack__ on a device other than the
// host's) hold pointers the CPU cannot read; numpy would fail on them with an unrelated message.
void refuseDeviceArray(py::handle obj, const std::string& name) {
  if (py::hasattr(obj, "__cuda_array_interface__"))
    throw tsah::ConfigError(name + ": a CUDA device array (__cuda_array_interface__); this call takes host arrays (numpy)");
  if (py::isinstance<py::array>(obj) || !py::hasattr(obj, "__dlpack_device__")) return;
  const auto device = obj.attr("__dlpack_device__")().cast<std::pair<int, int>>();
  if (device.first != dlpack::kCPU && device.first != dlpack::kCUDAHost)  // the host reads those
    throw tsah::ConfigError(name + ": a device array (DLPack device type " + std::to_string(device.first) +
                            "); this call takes host arrays (numpy)");
}

}  // namespace

template <class T>
Array<T> checkedArray(py::handle obj, const std::string& name, Kind kind,
                                                std::initializer_list<py::ssize_t> shape) {
  refuseDeviceArray(obj, name);
  if (!py::isinstance<py::array>(obj))
    throw ArgumentTypeError(name + ": expected a numpy array, got " +
                            std::string(py::str(obj.get_type().attr("__name__"))));
  const py::array a = py::reinterpret_borrow<py::array>(obj);
  if (!kindAccepts(kind, a.dtype().kind()))
    throw ArgumentTypeError(name + ": expected " + kindName(kind) + " array, got dtype " +
                            std::string(py::str(a.dtype())));
  bool shapeOk = a.ndim() == py::ssize_t(shape.size());
  std::size_t d = 0;
  for (py::ssize_t want : shape) {
    if (shapeOk && want >= 0 && a.shape(py::ssize_t(d)) != want) shapeOk = false;
    ++d;
  }
  if (!shapeOk) throw tsah::ConfigError(name + ": expected shape " + expectedShape(shape) + ", got " + shapeText(a));

  if constexpr (std::is_integral_v<T>) {
    // Check the range in 64 bits before narrowing, so -1 or 2**40 is an error, never a wrapped index.
    if (a.dtype().kind() == 'u') {
      const auto wide = py::array_t<uint64_t, py::array::c_style | py::array::forcecast>::ensure(a);
      const uint64_t* p = wide.data();
      for (py::ssize_t i = 0; i < wide.size(); ++i)
        if (p[i] > uint64_t(std::numeric_limits<T>::max()))
          throw tsah::ConfigError(name + ": value " + std::to_string(p[i]) + " is out of range");
    } else {
      const auto wide = py::array_t<int64_t, py::array::c_style | py::array::forcecast>::ensure(a);
      const int64_t* p = wide.data();
      for (py::ssize_t i = 0; i < wide.size(); ++i)
        if (p[i] < int64_t(std::numeric_limits<T>::min()) || uint64_t(p[i]) > uint64_t(std::numeric_limits<T>::max()))
          throw tsah::ConfigError(name + ": value " + std::to_string(p[i]) + " is out of range");
    }
  }
  if constexpr (std::is_same_v<T, float>) {
    // Wider floats must survive the narrowing: no finite value may become infinite (|v| > FLT_MAX)
    // or lose all its digits (0 < |v| < FLT_MIN, the smallest normal float32).
    if (a.dtype().kind() == 'f' && a.dtype().itemsize() > 4) {
      const auto wide = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
      const double* p = wide.data();
      for (py::ssize_t i = 0; i < wide.size(); ++i) {
        const double v = std::fabs(p[i]);
        if (std::isfinite(v) && (v > double(FLT_MAX) || (v > 0.0 && v < double(FLT_MIN))))
          throw tsah::ConfigError(name + ": value " + std::string(py::str(py::float_(p[i]))) + " (index " +
                                  std::to_string(i) + ") " + (v > 1.0 ? "overflows" : "underflows") + " float32");
      }
    }
  }
  auto result = Array<T>::ensure(a);
  if (!result) throw ArgumentTypeError(name + ": cannot convert dtype " + std::string(py::str(a.dtype())));
  return result;
}

template Array<float> checkedArray<float>(py::handle, const std::string&, Kind,
                                                                    std::initializer_list<py::ssize_t>);
template Array<double> checkedArray<double>(py::handle, const std::string&, Kind,
                                                                      std::initializer_list<py::ssize_t>);
template Array<uint32_t> checkedArray<uint32_t>(py::handle, const std::string&, Kind,
                                                                          std::initializer_list<py::ssize_t>);

}  // namespace tsah::python
