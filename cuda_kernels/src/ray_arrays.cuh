#pragma once
// Where a trace kernel reads its rays and times and writes its results: the packed records a host
// batch query uploads (Ray, one float time, InstanceHit), or the caller's own device arrays
// (device_arrays.hpp's ArrayRays and ArrayTimes, ArrayInstanceHits). One overload per form, so a
// kernel templated on the form is written once.
#include <cstdint>

#include "device_arrays.hpp"
#include "two_level_kernels.hpp"

namespace tsah::cuda::detail {

__device__ __forceinline__ Ray loadRay(const Ray* rays, uint32_t i) { return rays[i]; }

// A warp's three loads of 12-byte rows cover 384 contiguous bytes.
__device__ __forceinline__ Ray loadRay(const ArrayRays& r, uint32_t i) {
  const float* o = r.origins + 3 * std::size_t(i);
  const float* d = r.directions + 3 * std::size_t(i);
  Ray ray;
  ray.org = {__ldg(o), __ldg(o + 1), __ldg(o + 2)};
  ray.dir = {__ldg(d), __ldg(d + 1), __ldg(d + 2)};
  ray.tmin = r.tmin ? __ldg(r.tmin + i) : r.tminValue;
  ray.tmax = r.tmax ? __ldg(r.tmax + i) : r.tmaxValue;
  return ray;
}

__device__ __forceinline__ float loadTime(const float* times, uint32_t i) { return times[i]; }
__device__ __forceinline__ float loadTime(const ArrayTimes& t, uint32_t i) { return t.times ? __ldg(t.times + i) : t.value; }

// Packed: a miss as the host batch reads it (instance kNoHit).
__device__ __forceinline__ void storeInstanceHit(InstanceHit* hits, uint32_t i, const InstanceHit& h) { hits[i] = h; }

// Arrays: a miss as the Python module reports one (t = +inf, u = v = 0, both ids kNoHit).
__device__ __forceinline__ void storeInstanceHit(const ArrayInstanceHits& out, uint32_t i, const InstanceHit& h) {
  const bool hit = h.instance != kNoHit;
  if (out.t) out.t[i] = hit ? h.t : INFINITY;
  if (out.u) out.u[i] = hit ? h.u : 0.0f;
  if (out.v) out.v[i] = hit ? h.v : 0.0f;
  if (out.instance) out.instance[i] = hit ? h.instance : kNoHit;
  if (out.triangle) out.triangle[i] = hit ? h.prim : kNoHit;
}

}  // namespace tsah::cuda::detail
