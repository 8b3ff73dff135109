#include "tsah/base/binary_io.hpp"

#include <zlib.h>

namespace tsah {

// zlib's CRC-32 (the same polynomial and chaining as the files' checksums have always used), several
// times faster than a table-driven loop.
uint32_t crc32(const void* data, std::size_t size, uint32_t crc) {
  if (size == 0) return crc;  // zlib answers a null pointer (an empty vector's) with its start value
  return uint32_t(::crc32_z(crc, static_cast<const Bytef*>(data), size));
}

uint32_t crc32Combine(uint32_t first, uint32_t second, uint64_t secondBytes) {
  return uint32_t(::crc32_combine(first, second, z_off_t(secondBytes)));
}

std::vector<uint8_t> joinedBytes(std::span<const std::span<const uint8_t>> parts) {
  std::size_t size = 0;
  for (const std::span<const uint8_t> part : parts) size += part.size();
  std::vector<uint8_t> bytes;
  bytes.reserve(size);
  for (const std::span<const uint8_t> part : parts) bytes.insert(bytes.end(), part.begin(), part.end());
  return bytes;
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
