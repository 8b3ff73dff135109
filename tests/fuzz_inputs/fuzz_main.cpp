// libFuzzer entry: FUZZ_ENTRY (a compile definition) names the function of fuzz_entries.hpp.
#include <cstddef>
#include <cstdint>

#include "fuzz_entries.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tsah::fuzz::FUZZ_ENTRY({data, size});
  return 0;
}
