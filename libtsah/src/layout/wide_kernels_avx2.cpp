// The wide traversal kernels for AVX2 (4-wide VEX-encoded, 8-wide AVX). Compiled with -mavx2 -mfma
// -ffp-contract=off (CMakeLists.txt); only called after wideKernels() checked the processor.
#include <immintrin.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>

#include "layout/wide_kernels.hpp"

namespace tsah::isa_avx2 {
#include "layout/simd_sse.inl"
#include "layout/simd_avx.inl"
#include "layout/wide_kernels.inl"
}  // namespace tsah::isa_avx2

namespace tsah::detail {

WideKernels avx2Kernels() {
  WideKernels k;
  k.isa = SimdIsa::Avx2;
  k.closest4 = &isa_avx2::closestKernel<isa_avx2::V4>;
  k.any4 = &isa_avx2::anyKernel<isa_avx2::V4>;
  k.closest8 = &isa_avx2::closestKernel<isa_avx2::V8>;
  k.any8 = &isa_avx2::anyKernel<isa_avx2::V8>;
  k.woopRows4 = &isa_avx2::woopRowsKernel<4, isa_avx2::DoubleLanes4, isa_avx2::FloatLanes4, isa_avx2::IntLanes4>;
  k.woopRows8 = &isa_avx2::woopRowsKernel<8, isa_avx2::DoubleLanes8, isa_avx2::FloatLanes8, isa_avx2::IntLanes8>;
  return k;
}

}  // namespace tsah::detail
