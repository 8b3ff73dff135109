#pragma once
// Building blocks shared by the project's binary formats (.tanim in libanim, .tbvh in libtsah):
// a bounds-checked little-endian reader, a writer and CRC-32. Reading and writing whole files:
// files.hpp.
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "tsah/base/error.hpp"

namespace tsah {

static_assert(std::endian::native == std::endian::little,
              "the binary formats are little-endian and read in place; big-endian hosts need byte swaps");

// CRC-32 (IEEE 802.3, the zlib polynomial). Pass a previous result as `crc` to continue.
uint32_t crc32(const void* data, std::size_t size, uint32_t crc = 0);
// The CRC-32 of A followed by B from crc32(A), crc32(B) and B's length: checksums of parts
// computed apart (concurrently, or kept from before) make the whole's.
uint32_t crc32Combine(uint32_t first, uint32_t second, uint64_t secondBytes);

// Parts of a file (written one after the other by writeFileAtomically) joined into one buffer.
std::vector<uint8_t> joinedBytes(std::span<const std::span<const uint8_t>> parts);

// Reads fixed-width values from a byte buffer; every read is bounds-checked and a short buffer
// throws FileError naming the file, the byte offset and what was being read.
class ByteReader {
 public:
  ByteReader(std::span<const uint8_t> bytes, std::string file) : bytes_(bytes), file_(std::move(file)) {}

  template <typename T>
  T read(const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    T value;
    std::memcpy(&value, take(sizeof(T), what), sizeof(T));
    return value;
  }
  // Reads count values of T into out (resized). The size is checked against the bytes left before
  // anything is allocated, so a hostile count cannot trigger a huge allocation.
  template <typename T>
  void readArray(std::vector<T>& out, std::size_t count, const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (count > remaining() / sizeof(T))
      fail(std::string("truncated: ") + what + " needs " + std::to_string(count) + " x " +
           std::to_string(sizeof(T)) + " bytes, " + std::to_string(remaining()) + " left");
    out.resize(count);
    if (count) std::memcpy(out.data(), take(count * sizeof(T), what), count * sizeof(T));
  }
  std::span<const uint8_t> bytes(std::size_t n, const char* what) { return {take(n, what), n}; }

  std::size_t offset() const { return offset_; }
  std::size_t remaining() const { return bytes_.size() - offset_; }
  const std::string& file() const { return file_; }
  [[noreturn]] void fail(const std::string& what) const;

 private:
  const uint8_t* take(std::size_t n, const char* what);

  std::span<const uint8_t> bytes_;
  std::string file_;
  std::size_t offset_ = 0;
};

class ByteWriter {
 public:
  template <typename T>
  void write(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    append(&value, sizeof(T));
  }
  template <typename T>
  void writeArray(std::span<const T> values) {
    static_assert(std::is_trivially_copyable_v<T>);
    append(values.data(), values.size_bytes());
  }
  void append(const void* data, std::size_t size);
  std::vector<uint8_t>& buffer() { return buf_; }
  const std::vector<uint8_t>& buffer() const { return buf_; }

 private:
  std::vector<uint8_t> buf_;
};

}  // namespace tsah
