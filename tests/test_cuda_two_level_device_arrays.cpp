// GpuTwoLevelRuntime's device-array queries against its host batch queries: rays, times and results
// in the caller's device memory give the host batch's hits bit for bit (instant and blurred frames,
// per-ray and scalar times and limits, only the result arrays asked for), ordered with the caller's
// stream, and bad pointers are refused before anything is queued. Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cuda_runtime_api.h>

#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "cuda_test_support.hpp"
#include "cuda_two_level_fixture.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/scene/two_level.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/gpu_two_level.hpp"
#include "two_level_scene.hpp"

namespace fs = std::filesystem;

namespace {

namespace tc = tsah::cuda;
using Runtime = tc::GpuTwoLevelRuntime;

using Stream = tsah::test::CudaStream;

// Pinned host memory (what asynchronous copies need to be asynchronous).
template <class T>
class Pinned {
 public:
  explicit Pinned(std::size_t n) : n_(n) { CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&p_), n * sizeof(T))); }
  ~Pinned() { cudaFreeHost(p_); }
  Pinned(const Pinned&) = delete;
  Pinned& operator=(const Pinned&) = delete;
  T* data() { return p_; }
  std::size_t bytes() const { return n_ * sizeof(T); }
  std::vector<T> values() const { return std::vector<T>(p_, p_ + n_); }

 private:
  T* p_ = nullptr;
  std::size_t n_ = 0;
};

// The rays as the caller's arrays: origins and directions (n, 3), tmin and tmax (n,), and per-ray
// times (n,), filled on the caller's stream from pinned memory (the trace must wait for the copy).
struct CallerArrays {
  std::size_t n;
  Pinned<float> hostRows;  // origins, directions, tmin, tmax, times
  tc::DeviceBuffer<float> rows;
  CallerArrays(const std::vector<tsah::Ray>& rays, const std::vector<float>& times, const Stream& stream)
      : n(rays.size()), hostRows(rays.size() * 9), rows(rays.size() * 9) {
    float* o = hostRows.data();
    for (std::size_t i = 0; i < n; ++i) {
      const tsah::Ray& r = rays[i];
      const float row[] = {r.org.x, r.org.y, r.org.z};
      const float dir[] = {r.dir.x, r.dir.y, r.dir.z};
      std::memcpy(o + 3 * i, row, sizeof row);
      std::memcpy(o + 3 * n + 3 * i, dir, sizeof dir);
      o[6 * n + i] = r.tmin;
      o[7 * n + i] = r.tmax;
      o[8 * n + i] = times.empty() ? 0.0f : times[i];
    }
    CUDA_CHECK(cudaMemsetAsync(rows.data(), 0xff, rows.bytes(), stream.get()));  // NaNs until the copy
    CUDA_CHECK(cudaMemcpyAsync(rows.data(), hostRows.data(), hostRows.bytes(), cudaMemcpyHostToDevice, stream.get()));
  }
  Runtime::StreamHandle handle(const Stream& s) const { return s.get(); }
  tc::GpuRuntime::DeviceRays rays() const {
    const float* d = rows.data();
    return {d, d + 3 * n, d + 6 * n, d + 7 * n, 0.0f, std::numeric_limits<float>::infinity(), n};
  }
  Runtime::DeviceTimes times() const { return {rows.data() + 8 * n, 0.0f}; }
};

// The caller's result arrays, read back through the caller's stream only (after the trace's work,
// which the call ordered before anything queued there later).
struct CallerHits {
  std::size_t n;
  tc::DeviceBuffer<float> t, u, v;
  tc::DeviceBuffer<uint32_t> instance, triangle;
  tc::DeviceBuffer<uint8_t> occluded;
  explicit CallerHits(std::size_t count) : n(count), t(n), u(n), v(n), instance(n), triangle(n), occluded(n) {}
  Runtime::DeviceHits all() { return {t.data(), u.data(), v.data(), instance.data(), triangle.data()}; }
  template <class T>
  static std::vector<T> read(const tc::DeviceBuffer<T>& buffer, const Stream& stream) {
    Pinned<T> host(buffer.size());
    CUDA_CHECK(cudaMemcpyAsync(host.data(), buffer.data(), buffer.bytes(), cudaMemcpyDeviceToHost, stream.get()));
    stream.sync();
    return host.values();
  }
};

// The device results equal the host batch's bit for bit; a miss as the Python module reports it.
void expectSameHits(const std::vector<tsah::TwoLevelHit>& want, const std::vector<uint8_t>& wantAny,
                    const CallerHits& got, const Stream& stream) {
  const auto t = CallerHits::read(got.t, stream), u = CallerHits::read(got.u, stream),
             v = CallerHits::read(got.v, stream);
  const auto instance = CallerHits::read(got.instance, stream), triangle = CallerHits::read(got.triangle, stream);
  const auto occluded = CallerHits::read(got.occluded, stream);
  uint32_t hits = 0;
  for (std::size_t i = 0; i < want.size(); ++i) {
    ASSERT_EQ(occluded[i], wantAny[i]) << "ray " << i;
    if (want[i].valid()) {
      ++hits;
      ASSERT_EQ(instance[i], want[i].instance) << "ray " << i;
      ASSERT_EQ(triangle[i], want[i].prim) << "ray " << i;
      ASSERT_EQ(std::memcmp(&t[i], &want[i].t, 4), 0) << "ray " << i;
      ASSERT_EQ(std::memcmp(&u[i], &want[i].u, 4), 0) << "ray " << i;
      ASSERT_EQ(std::memcmp(&v[i], &want[i].v, 4), 0) << "ray " << i;
    } else {
      ASSERT_EQ(instance[i], tsah::kNoHit) << "ray " << i;
      ASSERT_EQ(triangle[i], tsah::kNoHit) << "ray " << i;
      ASSERT_EQ(t[i], std::numeric_limits<float>::infinity()) << "ray " << i;
      ASSERT_EQ(u[i], 0.0f);
      ASSERT_EQ(v[i], 0.0f);
    }
  }
  EXPECT_GT(hits, want.size() / 4);  // the comparison saw hits and misses
  EXPECT_LT(hits, want.size());
}

// Rays through the instances' boxes, some with tmin > 0 or a short tmax.
std::vector<tsah::Ray> raysFor(Runtime& gpu, uint32_t count, uint32_t seed) {
  const tsah::Aabb box = tsah::test::unionOf(gpu.downloadInstanceBoxes());
  std::vector<tsah::Ray> rays = tsah::test::raysThroughBox(box, count, seed);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (i % 7 == 0) rays[i].tmin = 0.3f;
    if (i % 5 == 0) rays[i].tmax = 0.8f;
  }
  return rays;
}

using CudaTwoLevelDeviceArrays = tsah::test::GpuTwoLevelSceneTest;

TEST_F(CudaTwoLevelDeviceArrays, InstantFramesGetTheHostBatchsHits) {
  for (const tc::TlasUpdate tlas : {tc::TlasUpdate::Refit, tc::TlasUpdate::Lbvh}) {
    SCOPED_TRACE(tc::tlasUpdateName(tlas));
    Runtime::Config config;
    config.tlas = tlas;
    Runtime gpu(*scene, config);
    Stream stream;
    for (const double time : {0.0, 3.25, 10.0}) {
      SCOPED_TRACE(time);
      gpu.updateAt(time);
      const std::vector<tsah::Ray> rays = raysFor(gpu, 3000, uint32_t(time * 4) + 1);
      const CallerArrays in(rays, {}, stream);
      CallerHits out(rays.size());
      gpu.closestHitsOnDevice(in.rays(), out.all(), in.handle(stream));
      gpu.anyHitsOnDevice(in.rays(), out.occluded.data(), in.handle(stream));
      expectSameHits(gpu.closestHits(rays), gpu.anyHits(rays), out, stream);
    }
  }
}

TEST_F(CudaTwoLevelDeviceArrays, ScalarLimitsAndSomeResultArrays) {
  Runtime gpu(*scene);
  gpu.updateAt(7.5);
  Stream stream;
  std::vector<tsah::Ray> rays = raysFor(gpu, 2000, 5);
  for (tsah::Ray& r : rays) r.tmin = 0.25f, r.tmax = 2.0f;
  const std::vector<tsah::TwoLevelHit> want = gpu.closestHits(rays);
  const std::vector<uint8_t> wantAny = gpu.anyHits(rays);
  const CallerArrays in(rays, {}, stream);
  tc::GpuRuntime::DeviceRays scalar = in.rays();
  scalar.tmin = scalar.tmax = nullptr;
  scalar.tminValue = 0.25f;
  scalar.tmaxValue = 2.0f;
  CallerHits out(rays.size());
  gpu.closestHitsOnDevice(scalar, {nullptr, nullptr, nullptr, out.instance.data(), out.triangle.data()},
                          in.handle(stream));
  gpu.anyHitsOnDevice(scalar, out.occluded.data(), in.handle(stream));
  const auto instance = CallerHits::read(out.instance, stream), triangle = CallerHits::read(out.triangle, stream);
  const auto occluded = CallerHits::read(out.occluded, stream);
  uint32_t hits = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    ASSERT_EQ(instance[i], want[i].valid() ? want[i].instance : tsah::kNoHit) << "ray " << i;
    ASSERT_EQ(triangle[i], want[i].valid() ? want[i].prim : tsah::kNoHit) << "ray " << i;
    ASSERT_EQ(occluded[i], wantAny[i]) << "ray " << i;
    hits += want[i].valid() ? 1 : 0;
  }
  EXPECT_GT(hits, 0u);
  EXPECT_LT(hits, rays.size());
}

TEST_F(CudaTwoLevelDeviceArrays, BlurredFramesTraceEachRayAtItsTime) {
  Runtime gpu(*scene);
  Stream stream;
  gpu.updateShutter(6.2, 6.9);
  ASSERT_TRUE(gpu.blurred());
  const std::vector<tsah::Ray> rays = raysFor(gpu, 3000, 9);
  std::vector<float> times(rays.size());
  for (std::size_t i = 0; i < times.size(); ++i) times[i] = i % 11 == 0 ? -0.5f : float(i % 97) / 96.0f;
  {  // per-ray times
    const CallerArrays in(rays, times, stream);
    CallerHits out(rays.size());
    gpu.closestHitsOnDevice(in.rays(), in.times(), out.all(), in.handle(stream));
    gpu.anyHitsOnDevice(in.rays(), in.times(), out.occluded.data(), in.handle(stream));
    expectSameHits(gpu.closestHits(rays, times), gpu.anyHits(rays, times), out, stream);
  }
  {  // one time for every ray
    const std::vector<float> same(rays.size(), 0.625f);
    const CallerArrays in(rays, {}, stream);
    CallerHits out(rays.size());
    gpu.closestHitsOnDevice(in.rays(), {nullptr, 0.625f}, out.all(), in.handle(stream));
    gpu.anyHitsOnDevice(in.rays(), {nullptr, 0.625f}, out.occluded.data(), in.handle(stream));
    expectSameHits(gpu.closestHits(rays, same), gpu.anyHits(rays, same), out, stream);
  }
  {  // times without a blurred frame: the instant
    gpu.updateAt(6.9);
    ASSERT_FALSE(gpu.blurred());
    const CallerArrays in(rays, times, stream);
    CallerHits out(rays.size());
    gpu.closestHitsOnDevice(in.rays(), in.times(), out.all(), in.handle(stream));
    gpu.anyHitsOnDevice(in.rays(), in.times(), out.occluded.data(), in.handle(stream));
    expectSameHits(gpu.closestHits(rays), gpu.anyHits(rays), out, stream);
  }
}

// The message of the tsah::ConfigError thrown by `call`.
template <class Call>
std::string configErrorOf(Call&& call) {
  try {
    call();
  } catch (const tsah::ConfigError& e) {
    return e.what();
  }
  return "(no tsah::ConfigError)";
}

TEST_F(CudaTwoLevelDeviceArrays, BadPointersAndLimitsAreRefused) {
  Runtime gpu(*scene);
  gpu.updateShutter(6.2, 6.9);
  Stream stream;
  const std::vector<tsah::Ray> rays = raysFor(gpu, 16, 3);
  const CallerArrays in(rays, std::vector<float>(rays.size(), 0.5f), stream);
  stream.sync();
  CallerHits out(rays.size());
  std::vector<float> host(rays.size() * 3);
  std::vector<uint8_t> hostFlags(rays.size());

  tc::GpuRuntime::DeviceRays hostOrigins = in.rays();
  hostOrigins.origins = host.data();
  EXPECT_EQ(configErrorOf([&] { gpu.closestHitsOnDevice(hostOrigins, out.all()); }),
            "GPU two-level runtime: origins: host memory, not device memory");
  tc::GpuRuntime::DeviceRays noDirections = in.rays();
  noDirections.directions = nullptr;
  EXPECT_EQ(configErrorOf([&] { gpu.anyHitsOnDevice(noDirections, out.occluded.data()); }),
            "GPU two-level runtime: directions: a null pointer");
  EXPECT_EQ(configErrorOf([&] { gpu.anyHitsOnDevice(in.rays(), hostFlags.data()); }),
            "GPU two-level runtime: occluded: host memory, not device memory");
  EXPECT_EQ(configErrorOf([&] { gpu.anyHitsOnDevice(in.rays(), nullptr); }),
            "GPU two-level runtime: occluded: a null pointer");
  Runtime::DeviceHits hostT = out.all();
  hostT.t = host.data();
  EXPECT_EQ(configErrorOf([&] { gpu.closestHitsOnDevice(in.rays(), hostT); }),
            "GPU two-level runtime: t: host memory, not device memory");
  EXPECT_EQ(configErrorOf([&] { gpu.closestHitsOnDevice(in.rays(), {host.data(), 0.0f}, out.all()); }),
            "GPU two-level runtime: times: host memory, not device memory");
  tc::GpuRuntime::DeviceRays badLimit = in.rays();
  badLimit.tmin = nullptr;
  badLimit.tminValue = -1.0f;
  EXPECT_EQ(configErrorOf([&] { gpu.closestHitsOnDevice(badLimit, out.all()); }),
            "GPU two-level runtime: tmin must be finite and >= 0");
  badLimit = in.rays();
  badLimit.tmax = nullptr;
  badLimit.tmaxValue = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(configErrorOf([&] { gpu.anyHitsOnDevice(badLimit, out.occluded.data()); }),
            "GPU two-level runtime: tmax is NaN");
  // No rays: nothing is checked or queued.
  EXPECT_NO_THROW(gpu.closestHitsOnDevice(tc::GpuRuntime::DeviceRays{}, Runtime::DeviceHits{}));
  // The refusals left the frame and the runtime usable.
  EXPECT_TRUE(gpu.blurred());
  gpu.closestHitsOnDevice(in.rays(), in.times(), out.all(), in.handle(stream));
  gpu.anyHitsOnDevice(in.rays(), in.times(), out.occluded.data(), in.handle(stream));
  stream.sync();
  const std::vector<float> times(rays.size(), 0.5f);
  const std::vector<tsah::TwoLevelHit> want = gpu.closestHits(rays, times);
  const auto instance = CallerHits::read(out.instance, stream);
  for (std::size_t i = 0; i < rays.size(); ++i)
    EXPECT_EQ(instance[i], want[i].valid() ? want[i].instance : tsah::kNoHit) << "ray " << i;
}

}  // namespace

#endif  // TSAH_HAVE_CUDA
