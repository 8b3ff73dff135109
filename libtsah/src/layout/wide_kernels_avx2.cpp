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

WideKernels avx2Kernels() { return isa_avx2::kernelTable<isa_avx2::V4, isa_avx2::V8>(SimdIsa::Avx2); }
WideVisitKernels avx2VisitKernels() { return isa_avx2::visitKernelTable<isa_avx2::V4, isa_avx2::V8>(); }

}  // namespace tsah::detail
