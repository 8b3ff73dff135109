// The GPU runtime's device-array arguments (docs/python.md#device-arrays): each checked through
// its protocol, the rays of a device batch assembled from them.
#if defined(TSAH_HAVE_CUDA)
#include <algorithm>

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

py::dict deviceHitArrays(DeviceArguments& args, py::handle out, const std::vector<DeviceHitField>& fields,
                         const std::vector<py::ssize_t>& batch, int device, std::vector<void*>& pointers) {
  std::string names;
  for (const DeviceHitField& f : fields) names += (names.empty() ? "" : ", ") + std::string(f.name);
  py::dict results;
  if (out.is_none()) {
    for (const DeviceHitField& f : fields) results[f.name] = newDeviceArray(batch, f.typestr, device, args.stream());
  } else if (py::isinstance<py::dict>(out)) {
    results = py::reinterpret_borrow<py::dict>(out);
    for (auto item : results) {
      const std::string key = py::str(item.first);
      if (std::none_of(fields.begin(), fields.end(), [&](const DeviceHitField& f) { return key == f.name; }))
        throw tsah::ConfigError("out: unknown field '" + key + "' (" + names + ")");
    }
  } else {
    throw ArgumentTypeError("out: expected a dict of device arrays (" + names + ") for device rays, got " +
                            std::string(py::str(out.get_type().attr("__name__"))));
  }
  pointers.assign(fields.size(), nullptr);
  for (std::size_t f = 0; f < fields.size(); ++f)
    if (results.contains(fields[f].name))
      pointers[f] = pointerOf<void>(
          args.add(results[fields[f].name], std::string("out['") + fields[f].name + "']", fields[f].accepted, batch, true));
  return results;
}

py::object deviceFlagArray(DeviceArguments& args, py::handle out, const std::vector<py::ssize_t>& batch, int device,
                           uint8_t** flags) {
  py::object result = out.is_none() ? newDeviceArray(batch, "|b1", device, args.stream())
                                    : py::reinterpret_borrow<py::object>(out);
  *flags = pointerOf<uint8_t>(args.add(result, "out", {"|b1", "|u1"}, batch, true));
  return result;
}

DeviceRayTimes deviceRayTimes(DeviceArguments& args, py::handle times, const std::vector<py::ssize_t>& batch) {
  DeviceRayTimes t;
  if (times.is_none()) return t;
  t.given = true;
  if (py::isinstance<py::float_>(times) || py::isinstance<py::int_>(times)) {
    t.value = times.cast<float>();
    return t;
  }
  if (!isDeviceArray(times))
    throw ArgumentTypeError("times: expected None, a number or a float32 device array like origins, got " +
                            std::string(py::str(times.get_type().attr("__name__"))));
  t.times = pointerOf<const float>(args.add(times, "times", {"<f4"}, batch));
  return t;
}

}  // namespace tsah::python

#endif  // TSAH_HAVE_CUDA
