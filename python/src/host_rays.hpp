#pragma once
// Host (numpy) rays and the result arrays of the runtimes' bindings (runtime.cpp defines them;
// runtime.cpp and two_level.cpp use them).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "bindings.hpp"
#include "tsah/core/ray.hpp"
#include "tsah/pipeline.hpp"  // RayArrays

namespace tsah::python {

// Rays given as numpy arrays: origins (..., 3), directions of the same shape, tmin and tmax each a
// number or an array of the batch shape (...), viewed as tsah::RayArrays (float32, used in place
// when the caller's arrays are float32 and C-contiguous; converted copies are kept here).
struct HostRays {
  Array<float> origins, directions;
  std::optional<Array<float>> tmin, tmax;  // none: the number below
  float tminValue = 0.0f, tmaxValue = 0.0f;
  std::vector<py::ssize_t> batch;  // the leading dimensions: the shape of the results
  RayArrays arrays;
};

// The arguments checked (shapes, dtypes; ConfigError / ArgumentTypeError naming the argument).
std::unique_ptr<HostRays> hostRays(py::handle origins, py::handle directions, py::handle tmin, py::handle tmax);

// A host batch's rays as Ray structs (GpuTracer's upload, CpuTracer's reference batch), left
// uninitialised until makeRays fills them in parallel (so that the first touch of their pages is
// parallel too).
struct RayBatch {
  std::unique_ptr<Ray[]> rays;
  std::size_t count = 0;
  operator std::span<const Ray>() const { return {rays.get(), count}; }
};

// The rays of hostRays as Ray structs, checked (checkRays). Returns the rays and the batch shape.
RayBatch makeRays(py::handle origins, py::handle directions, py::handle tmin, py::handle tmax,
                  std::vector<py::ssize_t>& batch);

// The array results go to: the caller's `out` (checked: a writeable C-contiguous numpy array of
// `dtype` and the batch shape) or a new one.
py::array resultArray(py::handle out, const py::dtype& dtype, const std::vector<py::ssize_t>& batch);

// Any-hit flags written into a bool array of the batch shape (returned).
py::array boolArray(const std::vector<uint8_t>& flags, py::array out);

}  // namespace tsah::python
