#pragma once
// CUDA device arrays in the Python module (docs/python.md#device-arrays): the caller's arrays read
// through __cuda_array_interface__ (v2, v3) or DLPack, used in place, and the module's own results
// on the device (tsah.DeviceArray, CUDA builds), which export both protocols.
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bindings.hpp"
#if defined(TSAH_HAVE_CUDA)
#include "tsah_cuda/gpu_runtime.hpp"
#endif

namespace tsah::python {

// DLPack's ABI (dlpack.h v0.8 and later; Debian's libdlpack-dev is 0.6, without the versioned
// tensor): the unversioned DLManagedTensor that travels in a capsule named "dltensor" (renamed
// "used_dltensor" by the consumer that takes it), and DLPack 1.0's ManagedTensorVersioned in one
// named "dltensor_versioned" ("used_dltensor_versioned").
namespace dlpack {
struct Device {
  int32_t type;
  int32_t id;
};
struct DataType {
  uint8_t code;
  uint8_t bits;
  uint16_t lanes;
};
struct Tensor {
  void* data;
  Device device;
  int32_t ndim;
  DataType dtype;
  int64_t* shape;
  int64_t* strides;  // in elements; null: C-contiguous
  uint64_t byteOffset;
};
struct ManagedTensor {
  Tensor tensor;
  void* managerCtx;
  void (*deleter)(ManagedTensor*);
};
// DLPack 1.0: a major version of another ABI leaves only `version` and `deleter` safe to read
// (the consumer must still call the deleter); a minor version adds codes, not fields.
struct Version {
  uint32_t major;
  uint32_t minor;
};
struct ManagedTensorVersioned {
  Version version;
  void* managerCtx;
  void (*deleter)(ManagedTensorVersioned*);
  uint64_t flags;
  Tensor tensor;
};
inline constexpr Version kVersion = {1, 0};  // the highest this module reads and writes
inline constexpr uint64_t kFlagReadOnly = 1, kFlagIsCopied = 2;
inline constexpr const char* kCapsule = "dltensor";
inline constexpr const char* kUsedCapsule = "used_dltensor";
inline constexpr const char* kVersionedCapsule = "dltensor_versioned";
inline constexpr const char* kUsedVersionedCapsule = "used_dltensor_versioned";
inline constexpr int32_t kCPU = 1, kCUDA = 2, kCUDAHost = 3, kCUDAManaged = 13;
inline constexpr uint8_t kInt = 0, kUInt = 1, kFloat = 2, kBool = 6;
}  // namespace dlpack

// True when obj offers device memory: a __cuda_array_interface__, or a __dlpack_device__ naming a
// CUDA device (kDLCUDA, kDLCUDAManaged). Host arrays (numpy, kDLCPU, kDLCUDAHost) are not.
bool isDeviceArray(py::handle obj);

// Within its scope (one call of the module, on one thread), each argument's
// __cuda_array_interface__ is read once and kept: torch builds it anew, in Python, at every access,
// and a call asks for it to tell device arrays apart and again to read them.
class InterfaceReadScope {
 public:
  InterfaceReadScope();
  ~InterfaceReadScope();
  InterfaceReadScope(const InterfaceReadScope&) = delete;
  InterfaceReadScope& operator=(const InterfaceReadScope&) = delete;

 private:
  bool outermost_ = false;
};

// A caller's device array, never copied: its pointer, C-contiguous shape and numpy typestr.
struct DeviceArrayArg {
  std::uintptr_t data = 0;
  std::vector<py::ssize_t> shape;
  std::string typestr;               // e.g. "<f4", "<i4", "|b1"
  std::optional<int> device;         // DLPack's device id (the CUDA interface names none)
  std::optional<std::uintptr_t> stream;  // CUDA interface v3: the stream its producer's work is on
  std::shared_ptr<void> hold;        // DLPack: the consumed tensor (its deleter runs with the last copy)
  std::size_t size() const;          // elements
};

// Reads obj's protocol and checks it before anything touches the device: typestr one of
// `typestrs` (ArgumentTypeError), C-contiguous, writable when `writable`, DLPack on device
// `device` (tsah::ConfigError); every message names `name`. DLPack: calls obj.__dlpack__(stream=
// consumerStream, max_version=(1, 0)) (the protocol's numbering: 1 the legacy default stream, 2 the
// per-thread one; again without max_version when that raises TypeError, as producers older than
// DLPack 1.0 do) and consumes the capsule, versioned (major version 1; read-only or copied refused
// when `writable`) or not: renamed "used_..."; its deleter runs when the result goes.
DeviceArrayArg checkedDeviceArray(py::handle obj, const std::string& name, const std::vector<std::string>& typestrs,
                                  bool writable, int device, std::uintptr_t consumerStream);

// The stream argument of the GPU runtime's methods as a cudaStream_t value: None (the legacy default
// stream, 0), an int, or an object with __cuda_stream__() ((version, address)) or cuda_stream.
std::uintptr_t streamArgument(py::handle stream);

// The protocols number the legacy default stream 1 (0 is ambiguous there); as a cudaStream_t it is 0.
inline std::uintptr_t protocolStream(std::uintptr_t stream) { return stream == 0 ? 1 : stream; }

// tsah._tsah._checked_device_array (the protocol checks, for tests on machines without a GPU) and,
// in CUDA builds, tsah.DeviceArray.
void bindDeviceArrays(py::module_& m);

#if defined(TSAH_HAVE_CUDA)
// tsah.DeviceArray (device_array_type.cpp): device memory the module owns, exported through both
// protocols; a new one of `shape` and typestr on `device`, its contents to be written in the order
// of `stream` (what its __cuda_array_interface__ and __dlpack__ tell consumers to wait for).
py::object newDeviceArray(const std::vector<py::ssize_t>& shape, const std::string& typestr, int device,
                          std::uintptr_t stream);
void bindDeviceArrayType(py::module_& m);
// The GPU runtime's arguments that may be device arrays (device_rays.cpp), checked in the order of
// the parameters and kept (DLPack: alive) until the call returns.
class DeviceArguments {
 public:
  DeviceArguments(int device, std::uintptr_t stream) : device_(device), stream_(stream) {}
  // checkedDeviceArray, and the shape when one is given.
  const DeviceArrayArg& add(py::handle obj, const std::string& name, const std::vector<std::string>& typestrs,
                            bool writable = false);
  const DeviceArrayArg& add(py::handle obj, const std::string& name, const std::vector<std::string>& typestrs,
                            const std::vector<py::ssize_t>& shape, bool writable = false);
  // Every array's producer stream (CUDA interface v3) is waited for on the call's stream.
  void waitForProducers() const;
  std::uintptr_t stream() const { return stream_; }

 private:
  int device_;
  std::uintptr_t stream_;
  std::deque<DeviceArrayArg> arrays_;  // stable references
};

template <class T>
T* pointerOf(const DeviceArrayArg& a) {
  return reinterpret_cast<T*>(a.data);
}

// origins and directions: float32 device arrays (..., 3) of one shape; tmin and tmax: numbers or
// float32 device arrays of the batch shape (...), which it sets.
cuda::GpuRuntime::DeviceRays deviceRays(DeviceArguments& args, py::handle origins, py::handle directions,
                                        py::handle tmin, py::handle tmax, std::vector<py::ssize_t>& batch);

// One result array of a device batch's closest hits: its key in the result dict, the typestr of a new
// one, the typestrs accepted from the caller (out=).
struct DeviceHitField {
  const char* name;
  const char* typestr;
  std::vector<std::string> accepted;
};
// The result arrays of a device batch: out None gives a new device array per field, a dict the
// caller's arrays for some of the fields (unknown keys refused); each checked through args (the
// batch shape, writable). Returns the dict; pointers[f] is field f's device pointer, null when absent.
py::dict deviceHitArrays(DeviceArguments& args, py::handle out, const std::vector<DeviceHitField>& fields,
                         const std::vector<py::ssize_t>& batch, int device, std::vector<void*>& pointers);

// The result of a device batch's any-hit query: out (None: a new bool device array of the batch
// shape; else the caller's, bool or uint8) checked through args; *flags its device pointer.
py::object deviceFlagArray(DeviceArguments& args, py::handle out, const std::vector<py::ssize_t>& batch, int device,
                           uint8_t** flags);

// times= of a device batch: None (no times), a number for every ray, or a float32 device array of
// the batch shape, checked through args.
struct DeviceRayTimes {
  bool given = false;
  const float* times = nullptr;
  float value = 0.0f;
};
DeviceRayTimes deviceRayTimes(DeviceArguments& args, py::handle times, const std::vector<py::ssize_t>& batch);

// The CUDA interface (v3) asks its consumer to wait for the producer's stream before using the
// data: makes `consumer` wait for a.stream (nothing when it names none or the same stream).
void waitForProducer(const DeviceArrayArg& a, std::uintptr_t consumer);
#endif

}  // namespace tsah::python
