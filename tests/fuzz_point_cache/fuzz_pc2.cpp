// libFuzzer entry point for the PC2 point-cache decoder: every input must be rejected with a
// one-line anim::ImportError or decode to a valid cache that survives an encode/decode round trip
// (point_cache_check.hpp); a crash, a sanitizer report, a hang or a huge allocation is a finding.
#include <cstdio>
#include <cstdlib>

#include "point_cache_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (const auto finding = anim::fuzz::pointCacheFinding({data, size}, anim::PointCacheFormat::Pc2)) {
    std::fprintf(stderr, "finding: %s\n", finding->c_str());
    std::abort();
  }
  return 0;
}
