// numpy argument checks of the Python module: wrong types raise tsah.ArgumentTypeError (a TypeError),
// wrong shapes or values tsah.ConfigError (a ValueError), always with the argument's name, before any
// data reaches the C++ API.
#include <limits>

#include "bindings.hpp"
#include "tsah/base/error.hpp"

namespace tsah::python {

std::string shapeText(const py::array& a) {
  std::string text = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) text += (d ? ", " : "") + std::to_string(a.shape(d));
  return text + (a.ndim() == 1 ? ",)" : ")");
}

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

}  // namespace

template <class T>
Array<T> checkedArray(py::handle obj, const std::string& name, Kind kind,
                                                std::initializer_list<py::ssize_t> shape) {
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
