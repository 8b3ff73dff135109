// libFuzzer entry: FUZZ_ENTRY (a compile definition, the target's name without fuzz_) names the
// function of entries.hpp.
#include <cstddef>
#include <cstdint>

#include "entries.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tsah::fuzz::FUZZ_ENTRY({data, size});
  return 0;
}
