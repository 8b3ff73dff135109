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

WideKernels avx512Kernels() { return isa_avx512::kernelTable<isa_avx512::V4, isa_avx512::V8>(SimdIsa::Avx512); }
WideVisitKernels avx512VisitKernels() { return isa_avx512::visitKernelTable<isa_avx512::V4, isa_avx512::V8>(); }

}  // namespace tsah::detail
