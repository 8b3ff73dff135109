#pragma once
// What every CUDA test program needs (include only where TSAH_HAVE_CUDA): skipping without a
// device, the short mode of the sanitizer runs, a stream of the test's own, runtime configurations, and the comparison of the
// compressed-layout GPU hits with the host reference and the binary layout.
#include <cuda_runtime_api.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "tsah/layout/cwbvh_build.hpp"
#include "tsah_cuda/cuda_check.hpp"
#include "tsah_cuda/device.hpp"
#include "tsah_cuda/gpu_runtime.hpp"
#include "test_support.hpp"

// Skips the test when the machine has no CUDA device (the CPU-only CI runs every CUDA test this way).
#define REQUIRE_GPU() \
  if (!tsah::cuda::deviceAvailable()) GTEST_SKIP() << "no CUDA device"

namespace tsah::test {

// TSAH_CUDA_TESTS=short (scripts/gpu-sanitize.sh sets it): smaller inputs and fewer rounds, so that
// every compute-sanitizer tool gets through a program in about a minute; the checks are the same.
inline bool shortCudaRun() {
  const char* value = std::getenv("TSAH_CUDA_TESTS");
  return value && std::string(value) == "short";
}

// A non-blocking CUDA stream of the test's own (a caller's stream for the device-array entry points).
class CudaStream {
 public:
  CudaStream() { CUDA_CHECK(cudaStreamCreateWithFlags(&s_, cudaStreamNonBlocking)); }
  ~CudaStream() { cudaStreamDestroy(s_); }
  CudaStream(const CudaStream&) = delete;
  CudaStream& operator=(const CudaStream&) = delete;
  cudaStream_t get() const { return s_; }
  void sync() const { CUDA_CHECK(cudaStreamSynchronize(s_)); }

 private:
  cudaStream_t s_ = nullptr;
};

inline cuda::GpuRuntime::Config gpuConfig(tsah::Layout layout, bool graphs = true) {
  cuda::GpuRuntime::Config c;
  c.layout = layout;
  c.useGraphs = graphs;
  return c;
}

// A GPU runtime's answers to a batch of rays.
struct GpuHits {
  std::vector<Hit> closest;
  std::vector<uint8_t> any;
};
inline GpuHits traceHits(cuda::GpuRuntime& gpu, std::span<const Ray> rays) {
  return {gpu.closestHits(rays), gpu.anyHits(rays)};
}

// The compressed-layout GPU hits `wide` against the host reference traversal of the same tree (view:
// bit-equal closest hits, the same any-hit answers) and against the binary GPU tree's hits `binary`
// (the same any-hit answers and validity, equal distances); adds the hits and the ties (another
// triangle at the same distance) to `count`.
inline void expectWideHitsMatch(const CwbvhView& view, std::span<const Ray> rays, const GpuHits& wide,
                                const GpuHits& binary, HitAgreement& count) {
  for (size_t i = 0; i < rays.size(); ++i) {
    // The GPU runs the reference code on the same data: bit-equal.
    const Hit ref = cwbvhClosestHit(view, rays[i]);
    ASSERT_EQ(std::memcmp(&ref, &wide.closest[i], sizeof ref), 0) << "ray " << i;
    ASSERT_EQ(wide.any[i] != 0, cwbvhAnyHit(view, rays[i])) << "ray " << i;
    // Against the binary tree: the same hit or none; another triangle only at the same distance.
    ASSERT_EQ(wide.any[i], binary.any[i]) << "ray " << i;
    ASSERT_EQ(wide.closest[i].valid(), binary.closest[i].valid()) << "ray " << i;
    if (!wide.closest[i].valid()) continue;
    ++count.hits;
    ASSERT_EQ(wide.closest[i].t, binary.closest[i].t) << "ray " << i;
    if (wide.closest[i].tri != binary.closest[i].tri) ++count.ties;
  }
}

}  // namespace tsah::test
