// The GPU runtime's device-array arguments (docs/python.md#device-arrays): each checked through
// its protocol, the rays of a device batch assembled from them.
#if defined(TSAH_HAVE_CUDA)
#include "device_arrays.hpp"

namespace tsah::python {

const DeviceArrayArg& DeviceArguments::add(py::handle obj, const std::string& name,
                                           const std::vector<std::string>& typestrs, bool writable) {
  arrays_.push_back(checkedDeviceArray(obj, name, typestrs, writable, device_, stream_));
  return arrays_.back();
}

const DeviceArrayArg& DeviceArguments::add(py::handle obj, const std::string& name,
                                           const std::vector<std::string>& typestrs,
                                           const std::vector<py::ssize_t>& shape, bool writable) {
  const DeviceArrayArg& a = add(obj, name, typestrs, writable);
  if (a.shape != shape)
    throw tsah::ConfigError(name + ": expected shape " + shapeText(shape) + ", got " + shapeText(a.shape));
  return a;
}

void DeviceArguments::waitForProducers() const {
  for (const DeviceArrayArg& a : arrays_) waitForProducer(a, stream_);
}

cuda::GpuRuntime::DeviceRays deviceRays(DeviceArguments& args, py::handle origins, py::handle directions,
                                        py::handle tmin, py::handle tmax, std::vector<py::ssize_t>& batch) {
  cuda::GpuRuntime::DeviceRays rays;
  const DeviceArrayArg& o = args.add(origins, "origins", {"<f4"});
  if (o.shape.empty() || o.shape.back() != 3)
    throw tsah::ConfigError("origins: expected shape (..., 3), got " + shapeText(o.shape));
  const DeviceArrayArg& d = args.add(directions, "directions", {"<f4"});
  if (d.shape != o.shape)
    throw tsah::ConfigError("directions: expected the shape of origins " + shapeText(o.shape) + ", got " +
                            shapeText(d.shape));
  batch.assign(o.shape.begin(), o.shape.end() - 1);
  rays.origins = pointerOf<const float>(o);
  rays.directions = pointerOf<const float>(d);
  rays.count = o.size() / 3;
  const auto limit = [&](py::handle value, const char* name, const float*& array, float& scalar) {
    if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)) {
      scalar = value.cast<float>();
      return;
    }
    if (!isDeviceArray(value))
      throw ArgumentTypeError(std::string(name) + ": expected a number or a float32 device array like origins, got " +
                              std::string(py::str(value.get_type().attr("__name__"))));
    array = pointerOf<const float>(args.add(value, name, {"<f4"}, batch));
  };
  limit(tmin, "tmin", rays.tmin, rays.tminValue);
  limit(tmax, "tmax", rays.tmax, rays.tmaxValue);
  return rays;
}

}  // namespace tsah::python

#endif  // TSAH_HAVE_CUDA
