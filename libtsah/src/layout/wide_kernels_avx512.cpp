// The wide traversal kernels for AVX-512 (AVX-512F/VL/DQ/BW: 4- and 8-wide with mask registers).
// Compiled with -mavx512f -mavx512vl -mavx512dq -mavx512bw -mavx2 -mfma -ffp-contract=off
// (CMakeLists.txt, only when the compiler accepts them); only called after wideKernels() checked
// the processor.
#include <immintrin.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>

#include "layout/wide_kernels.hpp"

namespace tsah::isa_avx512 {
#include "layout/simd_avx512.inl"
#include "layout/wide_kernels.inl"
}  // namespace tsah::isa_avx512

namespace tsah::detail {

WideKernels avx512Kernels() {
  WideKernels k;
  k.isa = SimdIsa::Avx512;
  k.closest4 = &isa_avx512::closestKernel<isa_avx512::V4>;
  k.any4 = &isa_avx512::anyKernel<isa_avx512::V4>;
  k.closest8 = &isa_avx512::closestKernel<isa_avx512::V8>;
  k.any8 = &isa_avx512::anyKernel<isa_avx512::V8>;
  k.woopRows4 = &isa_avx512::woopRowsKernel<4, isa_avx512::DoubleLanes4, isa_avx512::FloatLanes4, isa_avx512::IntLanes4>;
  k.woopRows8 = &isa_avx512::woopRowsKernel<8, isa_avx512::DoubleLanes8, isa_avx512::FloatLanes8, isa_avx512::IntLanes8>;
  return k;
}

}  // namespace tsah::detail
