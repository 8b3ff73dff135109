#pragma once
// Every CUDA runtime call goes through CUDA_CHECK, which turns a failure into a tsah::cuda::CudaError
// naming the call, the source location and CUDA's own description of the error.
#include <cuda_runtime_api.h>

#include <string>

#include "tsah/base/error.hpp"

namespace tsah::cuda {

// A failure of the device or the driver (a tsah::Failure): the request and the data were fine.
class CudaError : public tsah::Failure {
 public:
  CudaError(cudaError_t code, const std::string& what) : tsah::Failure(what), code_(code) {}
  cudaError_t code() const { return code_; }

 private:
  cudaError_t code_;
};

// Throws CudaError for anything but cudaSuccess. `call` is the text of the call.
void throwCudaError(cudaError_t code, const char* call, const char* file, int line);

inline void checkCuda(cudaError_t code, const char* call, const char* file, int line) {
  if (code != cudaSuccess) throwCudaError(code, call, file, line);
}

}  // namespace tsah::cuda

#define CUDA_CHECK(call) ::tsah::cuda::checkCuda((call), #call, __FILE__, __LINE__)
// After a kernel launch: a bad configuration is reported by cudaGetLastError.
#define CUDA_CHECK_LAUNCH(what) ::tsah::cuda::checkCuda(cudaGetLastError(), what, __FILE__, __LINE__)
