#pragma once
// Building blocks shared by the project's binary formats (.tanim here, .tbvh in libtsah):
// a bounds-checked little-endian reader, a writer, CRC-32, whole-file reads with a size limit and
// atomic writes (temporary file + rename, so an interrupted run never leaves a half-written file).
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "anim/error.hpp"

namespace anim {

static_assert(std::endian::native == std::endian::little,
              "the binary formats are little-endian and read in place; big-endian hosts need byte swaps");

// CRC-32 (IEEE 802.3, the zlib polynomial). Pass a previous result as `crc` to continue.
uint32_t crc32(const void* data, std::size_t size, uint32_t crc = 0);

// Reads fixed-width values from a byte buffer; every read is bounds-checked and a short buffer
// throws ImportError naming the file, the byte offset and what was being read.
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

// Reads a whole file; throws ImportError when it is missing, unreadable or larger than maxBytes.
std::vector<uint8_t> readFile(const std::string& path, std::size_t maxBytes = std::size_t(1) << 36);

// Writes bytes to `path` through a temporary file in the same folder and a rename; on any failure
// the temporary is removed and anim::Error is thrown naming the path.
void writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes);

}  // namespace anim
