// The wide traversal kernels for SSE2 (4-wide). Compiled with -ffp-contract=off (CMakeLists.txt).
#include <emmintrin.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>

#include "layout/wide_kernels.hpp"

namespace tsah::isa_sse {
#include "layout/simd_sse.inl"
#include "layout/wide_kernels.inl"
}  // namespace tsah::isa_sse

namespace tsah::detail {

WideKernels sseKernels() {
  WideKernels k;
  k.isa = SimdIsa::Sse;
  k.closest4 = &isa_sse::closestKernel<isa_sse::V4>;
  k.any4 = &isa_sse::anyKernel<isa_sse::V4>;
  k.woopRows4 = &isa_sse::woopRowsKernel<4, isa_sse::DoubleLanes4, isa_sse::FloatLanes4, isa_sse::IntLanes4>;
  k.woopRows8 = &isa_sse::woopRowsKernel<8, isa_sse::DoubleLanes8, isa_sse::FloatLanes8, isa_sse::IntLanes8>;
  return k;
}

}  // namespace tsah::detail
