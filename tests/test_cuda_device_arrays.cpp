// GpuRuntime's device-array entry points against its host ones: a refit from positions in device
// memory equals update(positions) (node boxes and Woop triangles bit for bit, both layouts, on a
// caller's stream), rays given as device arrays get the host batch's hits, and bad coordinates or
// pointers are refused with the host path's message. Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cuda_runtime_api.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "anim/generators.hpp"
#include "cuda_test_support.hpp"
#include "test_support.hpp"
#include "tsah/base/error.hpp"
#include "tsah/build/binned_sah_builder.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device_buffer.hpp"
#include "tsah_cuda/gpu_runtime.hpp"

namespace {

using tsah::Hit;
using tsah::Layout;
using tsah::Ray;
using tsah::Vec3;
namespace tc = tsah::cuda;

const anim::Animation& animation() {
  static const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Explode, 3000, 6, 3);
  return a;
}

const tsah::FlatBvh& tree() {
  static const tsah::FlatBvh t =
      tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(animation(), 0)));
  return t;
}

// Rays toward random points of the box from around it, and from inside it in any direction; some
// with tmin > 0 or a short tmax.
std::vector<Ray> randomRays(const tsah::Aabb& box, uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f), sym(-1.0f, 1.0f);
  const Vec3 size = box.extent();
  const auto inside = [&] { return box.lo + Vec3{unit(rng) * size.x, unit(rng) * size.y, unit(rng) * size.z}; };
  std::vector<Ray> rays(count);
  for (uint32_t i = 0; i < count; ++i) {
    const Vec3 target = inside();
    const Vec3 org = i % 3 == 0 ? target + Vec3{sym(rng), sym(rng), sym(rng)} * (2.0f * size.x) : inside();
    const Vec3 dir = i % 3 == 0 ? target - org : Vec3{sym(rng), sym(rng), sym(rng)};
    rays[i] = {org, i % 7 == 0 ? 0.01f * size.x : 0.0f, dir, i % 5 == 0 ? 0.1f * size.x : INFINITY};
  }
  return rays;
}

// The rays as Python's arrays give them: origins (n, 3), directions (n, 3), tmin (n,), tmax (n,).
struct RayArrays {
  tc::DeviceBuffer<float> origins, directions, tmin, tmax;
  explicit RayArrays(const std::vector<Ray>& rays) {
    std::vector<float> o, d, lo, hi;
    for (const Ray& r : rays) {
      o.insert(o.end(), {r.org.x, r.org.y, r.org.z});
      d.insert(d.end(), {r.dir.x, r.dir.y, r.dir.z});
      lo.push_back(r.tmin);
      hi.push_back(r.tmax);
    }
    origins = tc::DeviceBuffer<float>(std::span<const float>(o));
    directions = tc::DeviceBuffer<float>(std::span<const float>(d));
    tmin = tc::DeviceBuffer<float>(std::span<const float>(lo));
    tmax = tc::DeviceBuffer<float>(std::span<const float>(hi));
  }
  tc::GpuRuntime::DeviceRays view(std::size_t count) const {
    return {origins.data(), directions.data(), tmin.data(), tmax.data(), 0.0f, INFINITY, count};
  }
};

class Stream {
 public:
  Stream() { CUDA_CHECK(cudaStreamCreateWithFlags(&s_, cudaStreamNonBlocking)); }
  ~Stream() { cudaStreamDestroy(s_); }
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;
  cudaStream_t get() const { return s_; }
  void sync() const { CUDA_CHECK(cudaStreamSynchronize(s_)); }

 private:
  cudaStream_t s_ = nullptr;
};

// The traced tree of a runtime, bit for bit (binary: nodes and root box; cwbvh: compressed nodes),
// and its Woop triangles.
std::vector<uint8_t> frameBits(const tc::GpuRuntime& gpu) {
  std::vector<uint8_t> bits;
  const auto append = [&bits](const void* p, std::size_t n) {
    bits.insert(bits.end(), static_cast<const uint8_t*>(p), static_cast<const uint8_t*>(p) + n);
  };
  if (gpu.config().layout == Layout::Cwbvh) {
    const auto nodes = gpu.downloadCwbvhNodes();
    append(nodes.data(), nodes.size() * sizeof nodes[0]);
  } else {
    const tsah::FlatBvh t = gpu.downloadTree();
    append(t.nodes.data(), t.nodes.size() * sizeof t.nodes[0]);
  }
  const tsah::Aabb bounds = gpu.bounds();
  append(&bounds, sizeof bounds);
  const auto woop = gpu.downloadWoop();
  append(woop.data(), woop.size() * sizeof woop[0]);
  return bits;
}

class DeviceArrays : public ::testing::TestWithParam<Layout> {};

TEST_P(DeviceArrays, RefitFromDevicePositionsEqualsTheHostRefit) {
  REQUIRE_GPU();
  const anim::Animation& a = animation();
  tc::GpuRuntime host(tree(), a, tsah::test::gpuConfig(GetParam()));
  tc::GpuRuntime device(tree(), a, tsah::test::gpuConfig(GetParam()));
  Stream stream;
  // The caller's buffer starts as NaNs; each frame's positions reach it by an asynchronous copy on
  // the caller's stream, which the refit must wait for (a refit reading early would see NaNs).
  tc::DeviceBuffer<float> positions(std::size_t(a.vertexCount()) * 3);
  CUDA_CHECK(cudaMemset(positions.data(), 0xff, positions.bytes()));
  float* pinned = nullptr;
  CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&pinned), positions.bytes()));
  for (double t : a.uniformTimes(4)) {
    SCOPED_TRACE(t);
    const std::vector<float> p = a.positionsAt(t);
    host.update(p);
    std::memcpy(pinned, p.data(), positions.bytes());
    CUDA_CHECK(cudaMemcpyAsync(positions.data(), pinned, positions.bytes(), cudaMemcpyHostToDevice, stream.get()));
    device.updateFromDevice(positions.data(), a.vertexCount(), stream.get());
    stream.sync();
    EXPECT_EQ(device.downloadPositions(), p);
    EXPECT_TRUE(frameBits(device) == frameBits(host));
  }
  // An updateAt after a device refit refits everything again (the caller may have moved static vertices).
  device.updateAt(a.endTime());
  host.updateAt(a.endTime());
  EXPECT_TRUE(frameBits(device) == frameBits(host));
  CUDA_CHECK(cudaFreeHost(pinned));
}

TEST_P(DeviceArrays, RaysInDeviceArraysGetTheHostBatchsHits) {
  REQUIRE_GPU();
  const anim::Animation& a = animation();
  tc::GpuRuntime gpu(tree(), a, tsah::test::gpuConfig(GetParam()));
  gpu.updateAt(0.4 * a.endTime());
  const uint32_t n = tsah::test::shortCudaRun() ? 3000 : 20000;
  const std::vector<Ray> rays = randomRays(gpu.bounds(), n, 11);
  const std::vector<Hit> want = gpu.closestHits(rays);
  const std::vector<uint8_t> wantAny = gpu.anyHits(rays);
  const RayArrays arrays(rays);
  tc::DeviceBuffer<float> t(n), u(n), v(n);
  tc::DeviceBuffer<uint32_t> tri(n);
  tc::DeviceBuffer<uint8_t> occluded(n);
  Stream stream;
  gpu.closestHitsOnDevice(arrays.view(n), {t.data(), u.data(), v.data(), tri.data()}, stream.get());
  gpu.anyHitsOnDevice(arrays.view(n), occluded.data(), stream.get());
  stream.sync();
  const auto gotT = t.download(), gotU = u.download(), gotV = v.download();
  const auto gotTri = tri.download();
  const auto gotAny = occluded.download();
  uint32_t hits = 0;
  for (uint32_t i = 0; i < n; ++i) {
    ASSERT_EQ(gotTri[i], want[i].tri) << "ray " << i;
    ASSERT_EQ(gotAny[i], wantAny[i]) << "ray " << i;
    if (want[i].valid()) {
      ++hits;
      ASSERT_EQ(std::memcmp(&gotT[i], &want[i].t, 4), 0) << "ray " << i;
      ASSERT_EQ(std::memcmp(&gotU[i], &want[i].u, 4), 0) << "ray " << i;
      ASSERT_EQ(std::memcmp(&gotV[i], &want[i].v, 4), 0) << "ray " << i;
    } else {  // misses as the Python module reports them
      ASSERT_EQ(gotT[i], std::numeric_limits<float>::infinity()) << "ray " << i;
      ASSERT_EQ(gotU[i], 0.0f);
      ASSERT_EQ(gotV[i], 0.0f);
    }
  }
  // The comparison saw hits and misses (the exploding scene at 0.4 of its time leaves about one ray
  // in nine on a triangle).
  EXPECT_GT(hits, n / 20);
  EXPECT_LT(hits, n);

  // Scalar limits for every ray, and only the arrays asked for.
  std::vector<Ray> unbounded = rays;
  for (Ray& r : unbounded) r.tmin = 0.0f, r.tmax = 0.5f * gpu.bounds().extent().x;
  const std::vector<Hit> wantScalar = gpu.closestHits(unbounded);
  tc::GpuRuntime::DeviceRays scalar{arrays.origins.data(), arrays.directions.data(), nullptr, nullptr, 0.0f,
                                    0.5f * gpu.bounds().extent().x, n};
  tc::DeviceBuffer<uint32_t> triOnly(n);
  gpu.closestHitsOnDevice(scalar, {nullptr, nullptr, nullptr, triOnly.data()}, stream.get());
  stream.sync();
  const auto gotScalar = triOnly.download();
  for (uint32_t i = 0; i < n; ++i) ASSERT_EQ(gotScalar[i], wantScalar[i].tri) << "ray " << i;
}

INSTANTIATE_TEST_SUITE_P(Layouts, DeviceArrays, ::testing::Values(Layout::Bvh2, Layout::Cwbvh),
                         [](const auto& info) { return std::string(tsah::name(info.param)); });

// The message of tsah::DataError thrown by `call`.
template <class Call>
std::string dataErrorOf(Call&& call) {
  try {
    call();
  } catch (const tsah::DataError& e) {
    return e.what();
  }
  return "(no tsah::DataError)";
}

TEST(DeviceArrayErrors, BadCoordinatesAreRefusedAndLeaveTheFrame) {
  REQUIRE_GPU();
  const anim::Animation& a = animation();
  tc::GpuRuntime gpu(tree(), a);
  gpu.updateAt(0.0);
  const std::vector<uint8_t> before = frameBits(gpu);
  std::vector<float> p = a.positionsAt(0.5 * a.endTime());
  tc::DeviceBuffer<float> positions(p.size());
  const auto refitWith = [&](float value) {
    p[3 * 4 + 1] = value;
    p[3 * 9 + 2] = value;  // a later bad vertex: the first one is named
    positions.upload(std::span<const float>(p));
    CUDA_CHECK(cudaDeviceSynchronize());
    return dataErrorOf([&] { gpu.updateFromDevice(positions.data(), a.vertexCount()); });
  };
  EXPECT_EQ(refitWith(NAN), "positions: vertex 4 has a NaN or infinite coordinate");
  EXPECT_EQ(refitWith(-INFINITY), "positions: vertex 4 has a NaN or infinite coordinate");
  EXPECT_EQ(refitWith(1e30f),
            "positions: vertex 4 has coordinate 1e+30, beyond the supported magnitude 1e+18 (surface areas would overflow)");
  EXPECT_TRUE(frameBits(gpu) == before);
  EXPECT_EQ(refitWith(1e18f), "(no tsah::DataError)");  // the limit itself is accepted
  CUDA_CHECK(cudaDeviceSynchronize());
  EXPECT_EQ(dataErrorOf([&] { gpu.updateFromDevice(positions.data(), a.vertexCount() - 1); }),
            "GPU runtime: got " + std::to_string(a.vertexCount() - 1) + " vertices, expected " +
                std::to_string(a.vertexCount()));
}

TEST(DeviceArrayErrors, HostPointersAndBadLimitsAreRefused) {
  REQUIRE_GPU();
  const anim::Animation& a = animation();
  tc::GpuRuntime gpu(tree(), a);
  const std::vector<float> p = a.positionsAt(0.0);
  const auto configMessage = [](auto&& call) -> std::string {
    try {
      call();
    } catch (const tsah::ConfigError& e) {
      return e.what();
    }
    return "(no tsah::ConfigError)";
  };
  EXPECT_EQ(configMessage([&] { gpu.updateFromDevice(p.data(), a.vertexCount()); }),
            "GPU runtime: positions: host memory, not device memory");
  const std::vector<Ray> rays = randomRays(gpu.bounds(), 10, 1);
  const RayArrays arrays(rays);
  tc::DeviceBuffer<uint8_t> flags(10);
  gpu.updateAt(0.0);
  tc::GpuRuntime::DeviceRays bad = arrays.view(10);
  bad.directions = p.data();
  EXPECT_EQ(configMessage([&] { gpu.anyHitsOnDevice(bad, flags.data()); }),
            "GPU runtime: directions: host memory, not device memory");
  bad = arrays.view(10);
  bad.tmin = nullptr;
  bad.tminValue = -1.0f;
  EXPECT_EQ(configMessage([&] { gpu.anyHitsOnDevice(bad, flags.data()); }),
            "GPU runtime: tmin must be finite and >= 0");
  EXPECT_EQ(configMessage([&] { gpu.anyHitsOnDevice(arrays.view(10), nullptr); }),
            "GPU runtime: occluded: a null pointer");
}

}  // namespace

#endif  // TSAH_HAVE_CUDA
