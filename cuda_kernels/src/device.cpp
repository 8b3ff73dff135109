#include "tsah_cuda/device.hpp"

#include <cuda_runtime_api.h>

#include <cstring>

#include "tsah_cuda/cuda_check.hpp"

namespace tsah::cuda {

void throwCudaError(cudaError_t code, const char* call, const char* file, int line) {
  // Reset the runtime's last error, so that a later launch check does not report this one again
  // (a sticky error, one that breaks the context, stays regardless).
  (void)cudaGetLastError();
  const char* slash = std::strrchr(file, '/');
  throw CudaError(code, std::string("CUDA error in ") + call + " (" + (slash ? slash + 1 : file) + ":" +
                            std::to_string(line) + "): " + cudaGetErrorName(code) + ": " + cudaGetErrorString(code));
}

int deviceCount() {
  int count = 0;
  const cudaError_t status = cudaGetDeviceCount(&count);
  if (status != cudaSuccess) {
    (void)cudaGetLastError();  // clear the error so later calls do not report it
    return 0;
  }
  return count;
}

bool deviceAvailable() { return deviceCount() > 0; }

void useDevice(int index) { CUDA_CHECK(cudaSetDevice(index)); }

DeviceInfo describeDevice(int index) {
  cudaDeviceProp prop{};
  CUDA_CHECK(cudaGetDeviceProperties(&prop, index));
  DeviceInfo info;
  info.index = index;
  info.name = prop.name;
  info.computeMajor = prop.major;
  info.computeMinor = prop.minor;
  info.multiprocessors = prop.multiProcessorCount;
  info.globalMemoryBytes = prop.totalGlobalMem;
  info.l2CacheBytes = std::size_t(prop.l2CacheSize);
  CUDA_CHECK(cudaRuntimeGetVersion(&info.runtimeVersion));
  CUDA_CHECK(cudaDriverGetVersion(&info.driverVersion));
  return info;
}

}  // namespace tsah::cuda
