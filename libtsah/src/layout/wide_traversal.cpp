// The one dispatch point of the wide SIMD kernels: which instruction sets this build has and the
// processor runs (__builtin_cpu_supports), and their kernel tables.
#include "tsah/layout/wide_traversal.hpp"
#include "tsah/layout/wide_visit.hpp"

#include "tsah/base/error.hpp"
#include "layout/wide_kernels.hpp"

namespace tsah {

namespace {

struct KernelTables {
  bool supported[3] = {false, false, false};
  WideKernels table[3];
  WideVisitKernels visit[3];

  KernelTables() {
#if TSAH_HAVE_SSE_KERNELS
    table[0] = detail::sseKernels();
    visit[0] = detail::sseVisitKernels();
    supported[0] = true;  // SSE2 is part of x86-64
#endif
    // A table is made only where the processor runs its set: making it runs that set's code
    // (compiled with its flags, the constants may use its instructions).
#if TSAH_HAVE_AVX2_KERNELS
    __builtin_cpu_init();
    supported[1] = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    if (supported[1]) table[1] = detail::avx2Kernels(), visit[1] = detail::avx2VisitKernels();
#endif
#if TSAH_HAVE_AVX512_KERNELS
    supported[2] = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                   __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw") && supported[1];
    if (supported[2]) table[2] = detail::avx512Kernels(), visit[2] = detail::avx512VisitKernels();
#endif
  }
};

const KernelTables& tables() {
  static const KernelTables t;
  return t;
}

}  // namespace

bool isaSupported(SimdIsa isa) { return tables().supported[static_cast<int>(isa)]; }

std::vector<SimdIsa> supportedIsas() {
  std::vector<SimdIsa> out;
  for (SimdIsa isa : {SimdIsa::Sse, SimdIsa::Avx2, SimdIsa::Avx512})
    if (isaSupported(isa)) out.push_back(isa);
  return out;
}

SimdIsa bestIsa() {
  const auto all = supportedIsas();
  if (all.empty()) throw tsah::ConfigError("wide traversal: this build has no SIMD kernels for this processor");
  return all.back();
}

const WideKernels& wideKernels(SimdIsa isa) {
  if (!isaSupported(isa))
    throw tsah::ConfigError(std::string("wide traversal: the ") + name(isa) +
                      " kernels are not in this build or this processor does not run them");
  return tables().table[static_cast<int>(isa)];
}

const WideVisitKernels& wideVisitKernels(SimdIsa isa) {
  wideKernels(isa);  // the same check and error
  return tables().visit[static_cast<int>(isa)];
}

}  // namespace tsah
