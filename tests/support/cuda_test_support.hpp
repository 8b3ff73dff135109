#pragma once
// What every CUDA test program needs (include only where TSAH_HAVE_CUDA): skipping without a
// device, and the short mode of the sanitizer runs.
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "tsah_cuda/device.hpp"

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

}  // namespace tsah::test
