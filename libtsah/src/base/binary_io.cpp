#include "tsah/base/binary_io.hpp"

#include <array>

namespace tsah {

namespace {

// Slicing-by-8 tables: table[0] is the classic byte table, table[k][i] advances table[k-1][i] by
// one more zero byte, so eight input bytes are folded per step (several times faster than bytewise).
using CrcTables = std::array<std::array<uint32_t, 256>, 8>;
constexpr CrcTables makeCrcTables() {
  CrcTables t{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    t[0][i] = c;
  }
  for (uint32_t i = 0; i < 256; ++i)
    for (int k = 1; k < 8; ++k) t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xffu];
  return t;
}
constexpr CrcTables kCrc = makeCrcTables();

}  // namespace

uint32_t crc32(const void* data, std::size_t size, uint32_t crc) {
  const auto* p = static_cast<const uint8_t*>(data);
  crc = ~crc;
  for (; size >= 8; size -= 8, p += 8) {
    uint32_t lo, hi;
    std::memcpy(&lo, p, 4);
    std::memcpy(&hi, p + 4, 4);
    lo ^= crc;
    crc = kCrc[7][lo & 0xffu] ^ kCrc[6][(lo >> 8) & 0xffu] ^ kCrc[5][(lo >> 16) & 0xffu] ^ kCrc[4][lo >> 24] ^
          kCrc[3][hi & 0xffu] ^ kCrc[2][(hi >> 8) & 0xffu] ^ kCrc[1][(hi >> 16) & 0xffu] ^ kCrc[0][hi >> 24];
  }
  for (; size > 0; --size, ++p) crc = kCrc[0][(crc ^ *p) & 0xffu] ^ (crc >> 8);
  return ~crc;
}

void ByteReader::fail(const std::string& what) const {
  throw FileError(file_, "at byte " + std::to_string(offset_) + ": " + what);
}

const uint8_t* ByteReader::take(std::size_t n, const char* what) {
  if (n > remaining())
    fail(std::string("truncated: ") + what + " needs " + std::to_string(n) + " bytes, " +
         std::to_string(remaining()) + " left");
  const uint8_t* p = bytes_.data() + offset_;
  offset_ += n;
  return p;
}

void ByteWriter::append(const void* data, std::size_t size) {
  const auto* p = static_cast<const uint8_t*>(data);
  buf_.insert(buf_.end(), p, p + size);
}

}  // namespace tsah
