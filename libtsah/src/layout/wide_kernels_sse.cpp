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

WideKernels sseKernels() { return isa_sse::kernelTable<isa_sse::V4, void>(SimdIsa::Sse); }
WideVisitKernels sseVisitKernels() { return isa_sse::visitKernelTable<isa_sse::V4, void>(); }

}  // namespace tsah::detail
