#pragma once
// Private to libtsah: what the per-instruction-set kernel files (wide_kernels_<isa>.cpp) include
// before the SIMD types and wide_kernels.inl, and the factories each of them defines. Only
// wide_traversal.cpp (the one dispatch point) calls the factories.
#include <type_traits>

#include "tsah/core/ray.hpp"
#include "tsah/layout/motion_blur.hpp"
#include "tsah/layout/wide_layout.hpp"
#include "tsah/layout/wide_traversal.hpp"
#include "tsah/layout/wide_visit.hpp"
#include "tsah/layout/woop.hpp"

namespace tsah::detail {

#if TSAH_HAVE_SSE_KERNELS
WideKernels sseKernels();
WideVisitKernels sseVisitKernels();
#endif
#if TSAH_HAVE_AVX2_KERNELS
WideKernels avx2Kernels();
WideVisitKernels avx2VisitKernels();
#endif
#if TSAH_HAVE_AVX512_KERNELS
WideKernels avx512Kernels();
WideVisitKernels avx512VisitKernels();
#endif

}  // namespace tsah::detail
