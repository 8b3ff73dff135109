// libFuzzer entry point for the .tbvh reader. The first input byte chooses whether the checksum is
// repaired before decoding (odd: repaired), so mutations reach the structural checks behind it.
// Every input must either be rejected with anim::ImportError or decode to a tree that passes every
// invariant and re-encodes to the same bytes; anything else (crash, other exception, sanitizer
// report, huge allocation) is a finding.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "anim/binary_io.hpp"
#include "anim/error.hpp"
#include "tsah/bvh_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const bool repairChecksum = (data[0] & 1) != 0;
  std::vector<uint8_t> bytes(data + 1, data + size);
  if (repairChecksum && bytes.size() >= 4) {
    const uint32_t crc = anim::crc32(bytes.data(), bytes.size() - 4);
    std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
  }
  tsah::BvhFile file;
  try {
    file = tsah::decodeBvhFile(bytes, "fuzz.tbvh");
  } catch (const anim::ImportError&) {
    return 0;  // rejected with a clear error: fine
  }
  if (tsah::validate(file.bvh)) std::abort();  // accepted a broken tree
  // An accepted file is canonical: writing it again gives the same bytes.
  if (tsah::encodeBvhFile(file.bvh, file.info) != bytes) std::abort();
  return 0;
}
