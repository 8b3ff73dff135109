// GpuRuntime's device-array entry points against its host ones: a refit from positions in device
// memory equals update(positions) (node boxes and Woop triangles bit for bit, both layouts, on a
// caller's stream), rays given as device arrays get the host batch's hits, and bad coordinates or
// pointers are refused with the host path's message. Every test skips without a GPU.
#include <gtest/gtest.h>

#if TSAH_HAVE_CUDA

#include <cuda_runtime_api.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <string>
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

using Stream = tsah::test::CudaStream;

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

// The caller's buffer gets frame t's positions by an asynchronous copy on `stream` (which the
// refit must wait for); right after the call the caller overwrites it with NaNs on the same stream
// (which must wait for the refit's reads).
void refitThroughCallersStream(tc::GpuRuntime& gpu, tc::DeviceBuffer<float>& buffer, const float* pinned,
                               const Stream& stream, tc::GpuRuntime::DeviceCheck check) {
  CUDA_CHECK(cudaMemcpyAsync(buffer.data(), pinned, buffer.bytes(), cudaMemcpyHostToDevice, stream.get()));
  gpu.updateFromDevice(buffer.data(), buffer.size() / 3, stream.get(), check);
  CUDA_CHECK(cudaMemsetAsync(buffer.data(), 0xff, buffer.bytes(), stream.get()));
}

TEST_P(DeviceArrays, DeferredRefitEqualsTheHostRefitOnTheCallersStream) {
  REQUIRE_GPU();
  const anim::Animation& a = animation();
  for (bool graphs : {true, false}) {
    SCOPED_TRACE(graphs ? "graphs" : "separate launches");
    tc::GpuRuntime host(tree(), a, tsah::test::gpuConfig(GetParam(), graphs));
    tc::GpuRuntime device(tree(), a, tsah::test::gpuConfig(GetParam(), graphs));
    Stream stream;
    // Two buffers in turn: the captured graph must read the one given (the other holds NaNs).
    tc::DeviceBuffer<float> buffers[2] = {tc::DeviceBuffer<float>(std::size_t(a.vertexCount()) * 3),
                                          tc::DeviceBuffer<float>(std::size_t(a.vertexCount()) * 3)};
    float* pinned = nullptr;
    CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&pinned), buffers[0].bytes()));
    // The first frame follows no refit (it waits for its check), the others are queued without a wait.
    int frame = 0;
    for (double t : a.uniformTimes(6)) {
      SCOPED_TRACE(t);
      const std::vector<float> p = a.positionsAt(t);
      host.update(p);
      std::memcpy(pinned, p.data(), buffers[0].bytes());
      refitThroughCallersStream(device, buffers[frame++ / 2 % 2], pinned, stream, tc::GpuRuntime::DeviceCheck::Deferred);
      stream.sync();
      EXPECT_NO_THROW(device.checkDeviceUpdate());
      EXPECT_EQ(device.downloadPositions(), p);
      EXPECT_TRUE(frameBits(device) == frameBits(host));
    }
    CUDA_CHECK(cudaFreeHost(pinned));
  }
}

// A device buffer holding frame t's positions, or with a NaN at vertex 4 and 1e30 at vertex 9.
struct Frames {
  const anim::Animation& a;
  tc::DeviceBuffer<float> buffer;
  explicit Frames(const anim::Animation& anim) : a(anim), buffer(std::size_t(anim.vertexCount()) * 3) {}
  const float* good(double t) {
    buffer.upload(std::span<const float>(a.positionsAt(t)));
    CUDA_CHECK(cudaDeviceSynchronize());
    return buffer.data();
  }
  const float* bad(double t) {
    std::vector<float> p = a.positionsAt(t);
    p[3 * 4 + 1] = NAN;
    p[3 * 9 + 2] = 1e30f;
    buffer.upload(std::span<const float>(p));
    CUDA_CHECK(cudaDeviceSynchronize());
    return buffer.data();
  }
};

constexpr const char* kVertex4 = "positions: vertex 4 has a NaN or infinite coordinate";

TEST_P(DeviceArrays, RefusedFramesChangeNothingAndAreReportedOnce) {
  REQUIRE_GPU();
  using Check = tc::GpuRuntime::DeviceCheck;
  const anim::Animation& a = animation();
  tc::GpuRuntime gpu(tree(), a, tsah::test::gpuConfig(GetParam()));
  tc::GpuRuntime host(tree(), a, tsah::test::gpuConfig(GetParam()));
  Frames frames(a);
  const uint32_t n = a.vertexCount();
  const double end = a.endTime();
  gpu.updateAt(0.0);
  const auto goodFrame = [&](double t, Check check) {
    gpu.updateFromDevice(frames.good(t), n, nullptr, check);
    host.update(a.positionsAt(t));
    CUDA_CHECK(cudaDeviceSynchronize());
    EXPECT_TRUE(frameBits(gpu) == frameBits(host)) << "good frame at " << t;
  };
  for (int round = 0; round < 3; ++round) {  // good, bad, good, ... in both modes
    SCOPED_TRACE(round);
    goodFrame(0.2 * end + 0.1 * round, Check::Wait);
    const std::vector<uint8_t> before = frameBits(gpu);
    const std::vector<float> positionsBefore = gpu.downloadPositions();
    EXPECT_EQ(dataErrorOf([&] { gpu.updateFromDevice(frames.bad(0.9 * end), n, nullptr, Check::Wait); }), kVertex4);
    EXPECT_TRUE(frameBits(gpu) == before);
    EXPECT_EQ(gpu.downloadPositions(), positionsBefore);
    goodFrame(0.3 * end + 0.1 * round, Check::Deferred);
    const std::vector<uint8_t> deferredBefore = frameBits(gpu);
    // A Deferred refusal: the call returns, the frame stays, checkDeviceUpdate reports it once.
    EXPECT_EQ(dataErrorOf([&] { gpu.updateFromDevice(frames.bad(0.9 * end), n, nullptr, Check::Deferred); }),
              "(no tsah::DataError)");
    CUDA_CHECK(cudaDeviceSynchronize());
    EXPECT_TRUE(frameBits(gpu) == deferredBefore);
    EXPECT_EQ(gpu.downloadPositions(), a.positionsAt(0.3 * end + 0.1 * round));
    EXPECT_EQ(dataErrorOf([&] { gpu.checkDeviceUpdate(); }), kVertex4);
    EXPECT_EQ(dataErrorOf([&] { gpu.checkDeviceUpdate(); }), "(no tsah::DataError)");
    // ... or the next updateFromDevice does, and queues nothing: its good positions are not used.
    gpu.updateFromDevice(frames.bad(0.9 * end), n, nullptr, Check::Deferred);
    EXPECT_EQ(dataErrorOf([&] { gpu.updateFromDevice(frames.good(0.8 * end), n, nullptr, Check::Deferred); }),
              kVertex4);
    CUDA_CHECK(cudaDeviceSynchronize());
    EXPECT_TRUE(frameBits(gpu) == deferredBefore);
    // ... or updateAt, which then refits nothing either.
    gpu.updateFromDevice(frames.bad(0.9 * end), n, nullptr, Check::Deferred);
    EXPECT_EQ(dataErrorOf([&] { gpu.updateAt(0.7 * end); }), kVertex4);
    EXPECT_TRUE(frameBits(gpu) == deferredBefore);
    goodFrame(0.4 * end + 0.1 * round, Check::Deferred);
    EXPECT_NO_THROW(gpu.checkDeviceUpdate());
  }
}

TEST_P(DeviceArrays, ARefusedFrameAfterARebuildKeepsTheRebuiltTree) {
  REQUIRE_GPU();
  const anim::Animation& a = animation();
  tc::GpuRuntime gpu(tree(), a, tsah::test::gpuConfig(GetParam()));
  Frames frames(a);
  gpu.updateAt(0.0);
  gpu.rebuildAt(0.5 * a.endTime());
  const std::vector<Hit> hitsBefore = gpu.closestHits(randomRays(gpu.bounds(), 2000, 5));
  const std::vector<tsah::WoopTriangle> woopBefore = gpu.downloadWoop();
  // Refitting the uploaded tree again would replace the rebuilt frame: this refusal is thrown at once.
  EXPECT_EQ(dataErrorOf([&] {
              gpu.updateFromDevice(frames.bad(0.9 * a.endTime()), a.vertexCount(), nullptr,
                                   tc::GpuRuntime::DeviceCheck::Deferred);
            }),
            kVertex4);
  EXPECT_TRUE(gpu.tracingRebuiltTree());
  const std::vector<tsah::WoopTriangle> woopAfter = gpu.downloadWoop();
  EXPECT_EQ(std::memcmp(woopAfter.data(), woopBefore.data(), woopBefore.size() * sizeof woopBefore[0]), 0);
  const std::vector<Hit> hitsAfter = gpu.closestHits(randomRays(gpu.bounds(), 2000, 5));
  ASSERT_EQ(hitsAfter.size(), hitsBefore.size());
  for (std::size_t i = 0; i < hitsBefore.size(); ++i) ASSERT_EQ(hitsAfter[i].tri, hitsBefore[i].tri) << "ray " << i;
  // A good frame then refits the uploaded tree as usual.
  gpu.updateFromDevice(frames.good(0.6 * a.endTime()), a.vertexCount(), nullptr, tc::GpuRuntime::DeviceCheck::Deferred);
  EXPECT_NO_THROW(gpu.checkDeviceUpdate());
  EXPECT_FALSE(gpu.tracingRebuiltTree());
  EXPECT_EQ(gpu.downloadPositions(), a.positionsAt(0.6 * a.endTime()));
}

INSTANTIATE_TEST_SUITE_P(Layouts, DeviceArrays, ::testing::Values(Layout::Bvh2, Layout::Cwbvh),
                         [](const auto& info) { return std::string(tsah::name(info.param)); });

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


// The device time of a refit from device positions beside updateAt's (the runtime's own update,
// its captured graph): CUDA events on the caller's stream around the call, the median of several
// calls, printed for each check mode (docs/cuda-runtime.md#device-arrays). TSAH_DEVICE_REFIT_TRIANGLES
// sets the wave's size (default 400000; the short runs 20000). The refits must equal update(positions).
TEST(DeviceRefitTiming, PrintsTheTimesBesideUpdateAt) {
  REQUIRE_GPU();
  const char* size = std::getenv("TSAH_DEVICE_REFIT_TRIANGLES");
  const uint32_t triangles = size ? uint32_t(std::stoul(size)) : tsah::test::shortCudaRun() ? 20000u : 400000u;
  const anim::Animation a = tsah::test::generatedAnimation(anim::GeneratorKind::Wave, triangles, 10, 1);
  const tsah::FlatBvh t = tsah::flattenBvh(tsah::BinnedSahBuilder().build(tsah::test::keyframeBoxes(a, 0)));
  tc::GpuRuntime gpu(t, a);
  const double time = 0.5 * (a.startTime() + a.endTime());
  const std::vector<float> p = a.positionsAt(time);
  const tc::DeviceBuffer<float> positions{std::span<const float>(p)};
  CUDA_CHECK(cudaDeviceSynchronize());  // the upload ran on the legacy stream
  Stream stream;
  cudaEvent_t start = nullptr, stop = nullptr;
  CUDA_CHECK(cudaEventCreate(&start));
  CUDA_CHECK(cudaEventCreate(&stop));
  const int runs = 21;
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  std::vector<double> update;
  gpu.updateAt(time);  // captures its graph
  for (int r = 0; r < runs; ++r) update.push_back(gpu.updateAt(time).totalMs());
  const auto timeCalls = [&](tc::GpuRuntime::DeviceCheck check) {
    std::vector<double> ms;
    for (int r = 0; r <= runs; ++r) {  // the first call captures the graph
      CUDA_CHECK(cudaEventRecord(start, stream.get()));
      gpu.updateFromDevice(positions.data(), a.vertexCount(), stream.get(), check);
      CUDA_CHECK(cudaEventRecord(stop, stream.get()));
      CUDA_CHECK(cudaEventSynchronize(stop));
      float v = 0.0f;
      CUDA_CHECK(cudaEventElapsedTime(&v, start, stop));
      if (r > 0) ms.push_back(v);
    }
    gpu.checkDeviceUpdate();
    return median(ms);
  };
  const double wait = timeCalls(tc::GpuRuntime::DeviceCheck::Wait);
  const double deferred = timeCalls(tc::GpuRuntime::DeviceCheck::Deferred);
  const std::vector<uint8_t> fromDevice = frameBits(gpu);
  gpu.update(p);
  EXPECT_TRUE(frameBits(gpu) == fromDevice);
  const double own = median(update);
  std::printf("device refit, %u triangles, %u vertices: updateAt %.4f ms; updateFromDevice Wait %.4f ms (%.2fx), "
              "Deferred %.4f ms (%.2fx; target <= 1.2x)\n",
              a.triangleCount(), a.vertexCount(), own, wait, wait / own, deferred, deferred / own);
  RecordProperty("update_ms", std::to_string(own));
  RecordProperty("wait_ms", std::to_string(wait));
  RecordProperty("deferred_ms", std::to_string(deferred));
  CUDA_CHECK(cudaEventDestroy(start));
  CUDA_CHECK(cudaEventDestroy(stop));
}

}  // namespace

#endif  // TSAH_HAVE_CUDA
