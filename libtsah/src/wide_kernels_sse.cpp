// The wide traversal kernels for SSE2 (4-wide). Compiled with -ffp-contract=off (CMakeLists.txt).
#include <emmintrin.h>

#include <cstddef>
#include <cstdint>

#include "wide_kernels.hpp"

namespace tsah::isa_sse {
#include "simd_sse.inl"
#include "wide_kernels.inl"
}  // namespace tsah::isa_sse

namespace tsah::detail {

WideKernels sseKernels() {
  WideKernels k;
  k.isa = SimdIsa::Sse;
  k.closest4 = &isa_sse::closestKernel<isa_sse::V4>;
  k.any4 = &isa_sse::anyKernel<isa_sse::V4>;
  return k;
}

}  // namespace tsah::detail
