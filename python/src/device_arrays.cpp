// The caller's device arrays: __cuda_array_interface__ (v2, v3) and DLPack read in C++, with no
// torch or CuPy at build time; only the protocols' own fields are trusted, and every check runs
// before the device is touched.
#include "device_arrays.hpp"

#include <pybind11/stl.h>

#include <algorithm>
#include <optional>

namespace tsah::python {

namespace {

using namespace pybind11::literals;

using namespace dlpack;

// numpy's typestr of a DLPack dtype ("" for one numpy has no name for).
std::string typestrOf(const DataType& t) {
  if (t.lanes != 1 || t.bits % 8 != 0) return "";
  const std::string size = std::to_string(t.bits / 8);
  const std::string order = t.bits == 8 ? "|" : "<";
  switch (t.code) {
    case kInt: return order + "i" + size;
    case kUInt: return order + "u" + size;
    case kFloat: return order + "f" + size;
    case kBool: return t.bits == 8 ? "|b1" : "";
    default: return "";
  }
}

std::size_t itemsizeOf(const std::string& typestr) {
  return typestr.size() > 2 ? std::size_t(std::stoul(typestr.substr(2))) : 0;
}

// Whether byte strides (numpy's, the CUDA interface's) or element strides (DLPack's, scale 1) are
// those of a C-contiguous array of this shape; dimensions of extent 1 may have any stride.
bool cContiguous(const std::vector<py::ssize_t>& shape, const std::vector<py::ssize_t>& strides,
                 py::ssize_t itemStride) {
  py::ssize_t expected = itemStride;
  for (std::size_t d = shape.size(); d-- > 0;) {
    if (shape[d] != 1 && strides[d] != expected) return false;
    expected *= shape[d];
  }
  return true;
}

std::string typeName(py::handle obj) { return py::str(obj.get_type().attr("__name__")); }

void checkTypestr(const std::string& got, const std::string& name, const std::vector<std::string>& typestrs) {
  if (std::find(typestrs.begin(), typestrs.end(), got) != typestrs.end()) return;
  std::string wanted;
  for (std::size_t i = 0; i < typestrs.size(); ++i) wanted += (i ? " or '" : "'") + typestrs[i] + "'";
  throw ArgumentTypeError(name + ": expected a device array of typestr " + wanted + ", got '" + got + "'");
}

// The interfaces read in the current InterfaceReadScope (null outside one): per object, its
// interface or a null object when it has none. The objects are the call's arguments, alive for it.
thread_local std::vector<std::pair<PyObject*, py::object>>* interfaceReads = nullptr;

// obj.__cuda_array_interface__, or a null object when obj has none (reading it failed: torch raises
// AttributeError for a CPU tensor; hasattr's answer). Read once per call: torch builds the dict
// anew, in Python, at every access.
py::object cudaArrayInterfaceOf(py::handle obj) {
  if (py::isinstance<py::array>(obj)) return {};
  if (interfaceReads)
    for (const auto& [read, value] : *interfaceReads)
      if (read == obj.ptr()) return value;
  PyObject* value = PyObject_GetAttrString(obj.ptr(), "__cuda_array_interface__");
  if (!value) PyErr_Clear();
  py::object result = value ? py::reinterpret_steal<py::object>(value) : py::object();
  if (interfaceReads) interfaceReads->emplace_back(obj.ptr(), result);
  return result;
}

DeviceArrayArg fromCudaArrayInterface(const py::object& cai, const std::string& name, bool writable) {
  const auto bad = [&](const std::string& what) {
    return tsah::ConfigError(name + ": __cuda_array_interface__ " + what);
  };
  if (!py::isinstance<py::dict>(cai)) throw bad("is not a dict");
  const py::dict d = py::reinterpret_borrow<py::dict>(cai);
  for (const char* key : {"shape", "typestr", "data", "version"})
    if (!d.contains(key)) throw bad(std::string("has no '") + key + "'");
  DeviceArrayArg a;
  try {
    a.shape = d["shape"].cast<std::vector<py::ssize_t>>();
    a.typestr = d["typestr"].cast<std::string>();
    const auto data = d["data"].cast<std::pair<std::uintptr_t, bool>>();
    a.data = data.first;
    if (writable && data.second) throw bad("is read-only");
    const int version = d["version"].cast<int>();
    if (version < 2) throw bad("version " + std::to_string(version) + " is not supported (2 or 3)");
  } catch (const py::cast_error&) {
    throw bad("has a field of the wrong type (shape: tuple of int, typestr: str, data: (int, bool))");
  }
  if (std::any_of(a.shape.begin(), a.shape.end(), [](py::ssize_t n) { return n < 0; })) throw bad("has a negative extent");
  if (d.contains("mask") && !d["mask"].is_none()) throw bad("has a mask (masked arrays are not supported)");
  if (d.contains("strides") && !d["strides"].is_none()) {
    std::vector<py::ssize_t> strides;
    try {
      strides = d["strides"].cast<std::vector<py::ssize_t>>();
    } catch (const py::cast_error&) {
      throw bad("strides are not a tuple of int");
    }
    if (strides.size() != a.shape.size() || !cContiguous(a.shape, strides, py::ssize_t(itemsizeOf(a.typestr))))
      throw tsah::ConfigError(name + ": must be C-contiguous");
  }
  if (d.contains("stream") && !d["stream"].is_none()) {  // v3: the producer's stream; 0 is not allowed
    std::uintptr_t stream = 0;
    try {
      stream = d["stream"].cast<std::uintptr_t>();
    } catch (const py::cast_error&) {
      throw bad("stream is not a stream address (an int >= 1) or None");
    }
    if (stream == 0) throw bad("stream 0 is not allowed (1: the legacy default stream)");
    a.stream = stream;
  }
  return a;
}

// obj.__dlpack_device__(): (device type, device id).
std::pair<int, int> dlpackDevice(py::handle obj, const std::string& name) {
  try {
    return obj.attr("__dlpack_device__")().cast<std::pair<int, int>>();
  } catch (const py::cast_error&) {
    throw tsah::ConfigError(name + ": __dlpack_device__() must return (device type, device id)");
  }
}

// obj.__dlpack__(stream=S, max_version=(1, 0)); producers older than DLPack 1.0 take no
// max_version and raise TypeError: they are asked again without it.
py::object dlpackCapsule(py::handle obj, std::uintptr_t consumerStream) {
  const py::int_ stream(protocolStream(consumerStream));
  try {
    return obj.attr("__dlpack__")("stream"_a = stream, "max_version"_a = py::make_tuple(kVersion.major, kVersion.minor));
  } catch (py::error_already_set& e) {
    if (!e.matches(PyExc_TypeError)) throw;
  }
  return obj.attr("__dlpack__")("stream"_a = stream);
}

// A capsule's tensor, taken from it: the capsule renamed "used_...", so that it no longer deletes the
// tensor; `hold` calls the tensor's deleter when its last copy goes.
struct TakenTensor {
  const Tensor* tensor = nullptr;
  uint64_t flags = 0;  // versioned capsules only
  std::shared_ptr<void> hold;
};

template <class Managed>
Managed* takeCapsule(const py::object& capsule, const char* name, const char* usedName, TakenTensor& taken) {
  auto* managed = static_cast<Managed*>(PyCapsule_GetPointer(capsule.ptr(), name));
  if (!managed || PyCapsule_SetName(capsule.ptr(), usedName) != 0) throw py::error_already_set();
  taken.hold = std::shared_ptr<void>(managed, [](void* p) {
    auto* m = static_cast<Managed*>(p);
    if (m->deleter) m->deleter(m);
  });
  return managed;
}

TakenTensor takeDlpackTensor(const py::object& capsule, const std::string& name) {
  TakenTensor taken;
  if (PyCapsule_IsValid(capsule.ptr(), kVersionedCapsule)) {
    auto* managed = takeCapsule<ManagedTensorVersioned>(capsule, kVersionedCapsule, kUsedVersionedCapsule, taken);
    // Another major version has another layout: only the version and the deleter may be read.
    if (managed->version.major != kVersion.major)
      throw tsah::ConfigError(name + ": DLPack version " + std::to_string(managed->version.major) + "." +
                              std::to_string(managed->version.minor) + " is not supported (major version 1)");
    taken.flags = managed->flags;
    taken.tensor = &managed->tensor;
  } else if (PyCapsule_IsValid(capsule.ptr(), kCapsule)) {
    taken.tensor = &takeCapsule<ManagedTensor>(capsule, kCapsule, kUsedCapsule, taken)->tensor;
  } else {
    throw tsah::ConfigError(name + ": __dlpack__ did not return a DLPack capsule (or it was used already)");
  }
  return taken;
}

DeviceArrayArg fromDlpack(py::handle obj, const std::string& name, bool writable, int device,
                          std::uintptr_t consumerStream) {
  const auto where = dlpackDevice(obj, name);
  if (where.first != kCUDA && where.first != kCUDAManaged)
    throw tsah::ConfigError(name + ": a DLPack array on device type " + std::to_string(where.first) +
                            ", not a CUDA device");
  if (where.second != device)
    throw tsah::ConfigError(name + ": on CUDA device " + std::to_string(where.second) + "; the runtime uses device " +
                            std::to_string(device));
  const TakenTensor taken = takeDlpackTensor(dlpackCapsule(obj, consumerStream), name);
  DeviceArrayArg a;
  a.hold = taken.hold;  // deleted when the result goes, or now when a check below refuses it
  const Tensor& t = *taken.tensor;
  if (t.device.type != where.first || t.device.id != where.second)
    throw tsah::ConfigError(name + ": the DLPack tensor's device differs from __dlpack_device__'s");
  // The module writes into `writable` arrays: not into memory the producer marked read-only, nor
  // into a copy the producer made (the caller's array would never see the results).
  if (writable && (taken.flags & kFlagReadOnly)) throw tsah::ConfigError(name + ": the DLPack tensor is read-only");
  if (writable && (taken.flags & kFlagIsCopied))
    throw tsah::ConfigError(name + ": the DLPack tensor is a copy (results written into it would be lost)");
  a.shape.assign(t.shape, t.shape + t.ndim);
  a.typestr = typestrOf(t.dtype);
  a.device = t.device.id;
  a.data = reinterpret_cast<std::uintptr_t>(t.data) + t.byteOffset;
  if (t.strides && !cContiguous(a.shape, std::vector<py::ssize_t>(t.strides, t.strides + t.ndim), 1))
    throw tsah::ConfigError(name + ": must be C-contiguous");
  if (a.typestr.empty())
    throw ArgumentTypeError(name + ": a DLPack dtype numpy has no name for (code " + std::to_string(t.dtype.code) +
                            ", " + std::to_string(t.dtype.bits) + " bits, " + std::to_string(t.dtype.lanes) + " lanes)");
  return a;
}

// torch's objects that the direct read of a tensor compares with, once the caller has imported
// torch (the module never imports it); kept for the process.
struct TorchObjects {
  py::handle tensor;   // torch.Tensor
  py::handle strided;  // torch.strided
  std::vector<std::pair<py::handle, const char*>> dtypes;  // torch.float32 -> "<f4", ...
};

const TorchObjects* torchObjects() {
  static const TorchObjects* objects = nullptr;
  if (objects) return objects;
  static PyObject* const name = PyUnicode_InternFromString("torch");
  PyObject* torch = PyImport_GetModule(name);  // a new reference; null when torch is not imported
  if (!torch) {
    PyErr_Clear();
    return nullptr;
  }
  const py::object module = py::reinterpret_steal<py::object>(torch);
  try {
    auto* found = new TorchObjects;
    found->tensor = py::object(module.attr("Tensor")).release();
    found->strided = py::object(module.attr("strided")).release();
    for (const auto& [dtype, typestr] : {std::pair{"float32", "<f4"}, {"int32", "<i4"}, {"uint8", "|u1"}, {"bool", "|b1"}})
      found->dtypes.emplace_back(py::object(module.attr(dtype)).release(), typestr);
    objects = found;
  } catch (const py::error_already_set&) {  // torch still importing: the protocols serve this call
    return nullptr;
  }
  return objects;
}

// Whether obj is exactly a torch.Tensor (subclasses may change what the protocols say).
bool isPlainTorchTensor(py::handle obj, const TorchObjects*& torch) {
  torch = torchObjects();
  return torch && Py_TYPE(obj.ptr()) == reinterpret_cast<PyTypeObject*>(torch->tensor.ptr());
}

// A CUDA torch.Tensor read through the tensor's own attributes instead of its
// __cuda_array_interface__, a Python property that builds a new dict at every read (most of a
// short call's host time). Only the plain case: strided, C-contiguous, no autograd, a dtype of the
// table; anything else (nullopt) takes the protocols, with their checks and errors. The fields are
// the interface's: version 2, no stream, address 0 for an empty tensor.
std::optional<DeviceArrayArg> plainCudaTensor(py::handle obj) {
  const TorchObjects* torch = nullptr;
  if (!isPlainTorchTensor(obj, torch)) return std::nullopt;
  if (!obj.attr("is_cuda").cast<bool>() || obj.attr("requires_grad").cast<bool>() ||
      !py::object(obj.attr("layout")).is(torch->strided) || !obj.attr("is_contiguous")().cast<bool>())
    return std::nullopt;
  const py::object dtype = obj.attr("dtype");
  const auto known = std::find_if(torch->dtypes.begin(), torch->dtypes.end(),
                                  [&](const auto& entry) { return dtype.is(entry.first); });
  if (known == torch->dtypes.end()) return std::nullopt;
  DeviceArrayArg a;
  a.typestr = known->second;
  a.shape = obj.attr("shape").cast<std::vector<py::ssize_t>>();
  a.data = a.size() ? obj.attr("data_ptr")().cast<std::uintptr_t>() : 0;
  return a;
}

// A DLPack array on a device (not the host's memory, pinned or not).
bool isDlpackDeviceArray(py::handle obj) {
  if (py::isinstance<py::array>(obj)) return false;
  if (!py::hasattr(obj, "__dlpack_device__") || !py::hasattr(obj, "__dlpack__")) return false;
  const int type = dlpackDevice(obj, "array").first;
  return type != kCPU && type != kCUDAHost;
}

}  // namespace

std::size_t DeviceArrayArg::size() const {
  std::size_t n = 1;
  for (py::ssize_t extent : shape) n *= std::size_t(extent);
  return n;
}

bool isDeviceArray(py::handle obj) {
  const TorchObjects* torch = nullptr;
  if (isPlainTorchTensor(obj, torch)) return obj.attr("is_cuda").cast<bool>();
  return cudaArrayInterfaceOf(obj) || isDlpackDeviceArray(obj);
}

InterfaceReadScope::InterfaceReadScope() : outermost_(interfaceReads == nullptr) {
  if (outermost_) interfaceReads = new std::vector<std::pair<PyObject*, py::object>>();
}

InterfaceReadScope::~InterfaceReadScope() {
  if (!outermost_) return;
  delete interfaceReads;  // with the GIL held: the scope lives in a binding's body, outside any release
  interfaceReads = nullptr;
}

DeviceArrayArg checkedDeviceArray(py::handle obj, const std::string& name, const std::vector<std::string>& typestrs,
                                  bool writable, int device, std::uintptr_t consumerStream) {
  if (std::optional<DeviceArrayArg> tensor = plainCudaTensor(obj)) {
    checkTypestr(tensor->typestr, name, typestrs);
    return std::move(*tensor);
  }
  const py::object cai = cudaArrayInterfaceOf(obj);
  if (!cai && !isDlpackDeviceArray(obj))
    throw ArgumentTypeError(name + ": expected a CUDA device array (__cuda_array_interface__ or DLPack), got " +
                            typeName(obj));
  DeviceArrayArg a = cai ? fromCudaArrayInterface(cai, name, writable)
                         : fromDlpack(obj, name, writable, device, consumerStream);
  checkTypestr(a.typestr, name, typestrs);
  return a;
}

std::uintptr_t streamArgument(py::handle stream) {
  py::object value = py::reinterpret_borrow<py::object>(stream);
  if (stream.is_none()) return 0;
  if (PyLong_CheckExact(stream.ptr())) return checkedInteger<std::uintptr_t>(value, "stream");
  if (py::hasattr(stream, "__cuda_stream__")) {
    value = stream.attr("__cuda_stream__")();
    if (!py::isinstance<py::tuple>(value) || py::len(value) != 2)
      throw ArgumentTypeError("stream: __cuda_stream__() must return (version, address)");
    value = value[py::int_(1)];
  } else if (py::hasattr(stream, "cuda_stream")) {
    value = stream.attr("cuda_stream");
  }
  if (py::isinstance<py::bool_>(value) || !py::isinstance<py::int_>(value))
    throw ArgumentTypeError("stream: expected an int (a cudaStream_t), an object with __cuda_stream__ or cuda_stream, "
                            "or None; got " + typeName(stream));
  return checkedInteger<std::uintptr_t>(value, "stream");
}

void bindDeviceArrays(py::module_& m) {
  m.def(
      "_checked_device_array",
      [](py::handle obj, const std::string& name, const std::vector<std::string>& typestrs, bool writable, int device,
         py::handle stream) {
        const DeviceArrayArg a = checkedDeviceArray(obj, name, typestrs, writable, device, streamArgument(stream));
        py::dict out("data"_a = a.data, "shape"_a = py::tuple(py::cast(a.shape)), "typestr"_a = a.typestr);
        out["device"] = a.device ? py::object(py::int_(*a.device)) : py::object(py::none());
        out["stream"] = a.stream ? py::object(py::int_(*a.stream)) : py::object(py::none());
        return out;
      },
      "obj"_a, "name"_a, "typestrs"_a, "writable"_a = false, "device"_a = 0, "stream"_a = py::none(),
      "The protocol checks of a device argument, without touching the device (for tests).");
#if defined(TSAH_HAVE_CUDA)
  bindDeviceArrayType(m);
#endif
}

}  // namespace tsah::python
