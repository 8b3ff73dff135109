#pragma once
// Is there a CUDA device, and which.
#include <cstdint>
#include <string>

namespace tsah::cuda {

// True when a CUDA driver and at least one device are present. Never throws: a machine without a
// GPU or driver (CI) gets false, and the tests skip.
bool deviceAvailable();
// The number of CUDA devices (0 without a driver or a device). Never throws.
int deviceCount();
// Makes device `index` the calling thread's current device (cudaSetDevice): the GPU its kernels,
// allocations and the GPU optimizer use. Throws CudaError when it does not exist.
void useDevice(int index);

struct DeviceInfo {
  int index = 0;
  std::string name;
  int computeMajor = 0, computeMinor = 0;
  int multiprocessors = 0;
  std::size_t globalMemoryBytes = 0;
  std::size_t l2CacheBytes = 0;
  int runtimeVersion = 0, driverVersion = 0;  // e.g. 13000 for CUDA 13.0
};

// Properties of device `index`; throws CudaError when it does not exist.
DeviceInfo describeDevice(int index = 0);

}  // namespace tsah::cuda
