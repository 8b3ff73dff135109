// tsah.DeviceArray: device memory the module owns (the results of a GPU runtime's trace on device
// rays), exported without a copy through __cuda_array_interface__ (v3) and DLPack, so that
// torch.from_dlpack(a) and cupy.asarray(a) take it as it is.
#if defined(TSAH_HAVE_CUDA)
#include <cuda_runtime_api.h>
#include <pybind11/stl.h>

#include <memory>
#include <type_traits>

#include "device_arrays.hpp"
#include "tsah_cuda/cuda_check.hpp"

namespace tsah::python {

namespace {

using namespace pybind11::literals;

// What a capsule's tensor owns: its shape, and a reference to the DeviceArray holding the memory.
// The capsule carries `managed` (unversioned) or `versioned` (DLPack 1.0), as the consumer asked.
struct Export {
  dlpack::ManagedTensor managed{};
  dlpack::ManagedTensorVersioned versioned{};
  std::vector<int64_t> shape;
  PyObject* owner = nullptr;
};

// The deleter of either kind of tensor.
template <class Managed>
void deleteExport(Managed* t) {
  auto* e = static_cast<Export*>(t->managerCtx);
  const PyGILState_STATE gil = PyGILState_Ensure();  // consumers may delete from any thread
  Py_XDECREF(e->owner);
  PyGILState_Release(gil);
  delete e;
}

template <class Managed>
constexpr const char* capsuleName() {
  return std::is_same_v<Managed, dlpack::ManagedTensor> ? dlpack::kCapsule : dlpack::kVersionedCapsule;
}

// The capsule's destructor: a tensor nobody consumed (the capsule still has its first name) is
// deleted here.
template <class Managed>
void deleteUnusedCapsule(PyObject* capsule) {
  if (!PyCapsule_IsValid(capsule, capsuleName<Managed>())) return;
  auto* t = static_cast<Managed*>(PyCapsule_GetPointer(capsule, capsuleName<Managed>()));
  if (t && t->deleter) t->deleter(t);
}

template <class Managed>
py::capsule newCapsule(Managed* managed) {
  PyObject* capsule = PyCapsule_New(managed, capsuleName<Managed>(), deleteUnusedCapsule<Managed>);
  if (!capsule) {
    managed->deleter(managed);
    throw py::error_already_set();
  }
  return py::reinterpret_steal<py::capsule>(capsule);
}

// max_version's major version: the protocol's (major, minor), a tuple of ints.
long long maxVersionMajor(py::handle maxVersion) {
  try {
    return maxVersion.cast<std::pair<long long, long long>>().first;
  } catch (const py::cast_error&) {
    throw ArgumentTypeError("max_version: expected (major, minor), a tuple of two ints, or None");
  }
}

// `consumer` waits for the work queued on `producer` so far (cudaStream_t values).
void streamWaits(std::uintptr_t consumer, std::uintptr_t producer) {
  cudaEvent_t ready = nullptr;
  CUDA_CHECK(cudaEventCreateWithFlags(&ready, cudaEventDisableTiming));
  CUDA_CHECK(cudaEventRecord(ready, reinterpret_cast<cudaStream_t>(producer)));
  CUDA_CHECK(cudaStreamWaitEvent(reinterpret_cast<cudaStream_t>(consumer), ready, 0));
  CUDA_CHECK(cudaEventDestroy(ready));  // released once the wait is done
}

}  // namespace

void waitForProducer(const DeviceArrayArg& a, std::uintptr_t consumer) {
  if (a.stream && *a.stream != protocolStream(consumer)) streamWaits(consumer, *a.stream);
}

class DeviceArray {
 public:
  DeviceArray(std::vector<py::ssize_t> shape, std::string typestr, int device, std::uintptr_t stream)
      : shape_(std::move(shape)), typestr_(std::move(typestr)), device_(device), stream_(stream) {
    static const std::vector<std::string> known = {"<f4", "<i4", "<u4", "|b1", "|u1"};
    if (std::find(known.begin(), known.end(), typestr_) == known.end())
      throw ArgumentTypeError("typestr: expected '<f4', '<i4', '<u4', '|b1' or '|u1', got '" + typestr_ + "'");
    std::size_t bytes = typestr_[2] == '4' ? 4 : 1;
    for (py::ssize_t n : shape_) {
      if (n < 0) throw tsah::ConfigError("shape: extents must be >= 0, got " + shapeText(shape_));
      bytes *= std::size_t(n);
    }
    // Plain cudaMalloc, not DeviceBuffer (which zeroes and waits for the legacy stream): making the
    // results of a device trace must not wait for the device. cudaFree waits for it when the array goes.
    int current = 0;
    CUDA_CHECK(cudaGetDevice(&current));
    CUDA_CHECK(cudaSetDevice(device_));
    void* p = nullptr;
    const cudaError_t allocated = bytes ? cudaMalloc(&p, bytes) : cudaSuccess;
    CUDA_CHECK(cudaSetDevice(current));
    CUDA_CHECK(allocated);
    memory_.reset(p);
  }
  std::uintptr_t data() const { return reinterpret_cast<std::uintptr_t>(memory_.get()); }
  py::tuple shape() const { return py::tuple(py::cast(shape_)); }
  const std::string& typestr() const { return typestr_; }
  int device() const { return device_; }

  // Version 3: C-contiguous (strides None), writable; stream: the stream its contents are ordered on
  // (the legacy default stream is 1 there).
  py::dict cudaArrayInterface() const {
    return py::dict("shape"_a = shape(), "typestr"_a = typestr_, "data"_a = py::make_tuple(data(), false),
                    "version"_a = 3, "strides"_a = py::none(), "stream"_a = protocolStream(stream_));
  }
  py::tuple dlpackDevice() const { return py::make_tuple(dlpack::kCUDA, device_); }
  // The protocol's __dlpack__: the consumer's stream waits for this array's (none when it is -1 or
  // the same); a DLPack 1.0 capsule ("dltensor_versioned", version 1.0, no flags) when the consumer
  // reads one (max_version's major >= 1), else the unversioned "dltensor"; never a copy.
  py::capsule dlpack(py::handle self, py::handle stream, py::handle maxVersion, py::handle dlDevice,
                     py::handle copy) const {
    if (!copy.is_none() && copy.cast<bool>()) throw py::buffer_error("tsah.DeviceArray: __dlpack__ makes no copies");
    if (!dlDevice.is_none() && dlDevice.cast<std::pair<int, int>>() != std::pair<int, int>(dlpack::kCUDA, device_))
      throw py::buffer_error("tsah.DeviceArray: lives on CUDA device " + std::to_string(device_));
    const bool versioned = !maxVersion.is_none() && maxVersionMajor(maxVersion) >= dlpack::kVersion.major;
    const long long consumer = stream.is_none() ? 1 : stream.cast<long long>();  // None: the legacy default
    if (consumer != -1 && std::uintptr_t(consumer) != protocolStream(stream_)) streamWaits(std::uintptr_t(consumer), stream_);
    auto* e = new Export;
    e->shape.assign(shape_.begin(), shape_.end());
    e->owner = self.inc_ref().ptr();
    const char kind = typestr_[1];
    const uint8_t code = kind == 'f' ? dlpack::kFloat : kind == 'i' ? dlpack::kInt : kind == 'b' ? dlpack::kBool : dlpack::kUInt;
    const dlpack::Tensor tensor = {memory_.get(), {dlpack::kCUDA, device_}, int32_t(shape_.size()),
                                   {code, uint8_t(typestr_[2] == '4' ? 32 : 8), 1}, e->shape.data(), nullptr, 0};
    if (versioned) {
      e->versioned = {dlpack::kVersion, e, deleteExport<dlpack::ManagedTensorVersioned>, 0, tensor};
      return newCapsule(&e->versioned);
    }
    e->managed = {tensor, e, deleteExport<dlpack::ManagedTensor>};
    return newCapsule(&e->managed);
  }

 private:
  std::vector<py::ssize_t> shape_;
  std::string typestr_;
  int device_;
  std::uintptr_t stream_;  // cudaStream_t value: 0 the legacy default stream
  struct Free {
    void operator()(void* p) const noexcept { cudaFree(p); }
  };
  std::unique_ptr<void, Free> memory_;
};

py::object newDeviceArray(const std::vector<py::ssize_t>& shape, const std::string& typestr, int device,
                          std::uintptr_t stream) {
  return py::cast(std::make_unique<DeviceArray>(shape, typestr, device, stream));
}

void bindDeviceArrayType(py::module_& m) {
  py::class_<DeviceArray>(m, "DeviceArray", R"doc(
DeviceArray(shape, typestr="<f4", device=0): C-contiguous memory on a CUDA device owned by the module
(a GPU runtime's results for device rays, or an out= array made here), uninitialised. Exported
without a copy: __cuda_array_interface__ (version 3) and __dlpack__ / __dlpack_device__, so
torch.from_dlpack(a), cupy.asarray(a) and numba take it. typestr: '<f4', '<i4', '<u4', '|b1', '|u1'.
)doc")
      .def(py::init([](py::handle shape, const std::string& typestr, py::handle device) {
             std::vector<py::ssize_t> extents;
             for (py::handle n : py::iter(shape)) extents.push_back(checkedInteger<py::ssize_t>(n, "shape"));
             return std::make_unique<DeviceArray>(std::move(extents), typestr, checkedInteger<int>(device, "device", 0), 0);
           }),
           "shape"_a, "typestr"_a = "<f4", "device"_a = 0)
      .def_property_readonly("shape", &DeviceArray::shape, "The shape, a tuple.")
      .def_property_readonly("typestr", &DeviceArray::typestr, "numpy's typestr of the elements, e.g. '<f4'.")
      .def_property_readonly("device", &DeviceArray::device, "The CUDA device the memory is on.")
      .def_property_readonly("__cuda_array_interface__", &DeviceArray::cudaArrayInterface,
                             "The CUDA array interface, version 3.")
      .def("__dlpack_device__", &DeviceArray::dlpackDevice, "(2, device): kDLCUDA and the device.")
      .def(
          "__dlpack__",
          [](py::handle self, py::handle stream, py::handle maxVersion, py::handle dlDevice, py::handle copy) {
            return self.cast<const DeviceArray&>().dlpack(self, stream, maxVersion, dlDevice, copy);
          },
          py::kw_only(), "stream"_a = py::none(), "max_version"_a = py::none(), "dl_device"_a = py::none(),
          "copy"_a = py::none(),
          "A DLPack capsule of the array (no copy), after the consumer's stream waits for it: DLPack 1.0's\n"
          "'dltensor_versioned' when max_version's major is 1 or more, else the unversioned 'dltensor'.");
}

}  // namespace tsah::python

#endif  // TSAH_HAVE_CUDA
