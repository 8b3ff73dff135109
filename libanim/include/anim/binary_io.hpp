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

// Opens an input for reading. Only regular files are accepted: a FIFO would block forever, a
// device never ends and a folder is not a file, so each is refused with a message naming it (the
// check uses the opened descriptor, so the file cannot change kind in between). Every reader of the
// project goes through this (readFile, and checkInputFile for libraries that open files themselves).
class InputFile {
 public:
  explicit InputFile(const std::string& path, bool protect = true);
  ~InputFile();
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;
  int fd() const { return fd_; }
  std::size_t size() const { return size_; }

 private:
  int fd_ = -1;
  std::size_t size_ = 0;
};

// For readers that open the file themselves (OpenMesh, Assimp): the same checks as InputFile.
void checkInputFile(const std::string& path);

// Reads a whole file; throws ImportError when it is missing, not a regular file, unreadable or
// larger than maxBytes.
std::vector<uint8_t> readFile(const std::string& path, std::size_t maxBytes = std::size_t(1) << 36);
// readFile for a file the command means to rewrite (a report updated in place): not protected.
std::vector<uint8_t> readFileForUpdate(const std::string& path, std::size_t maxBytes);

// When on (the command line turns it on), every file opened as an input is remembered and the
// writers below refuse to replace one of them: `optimize a.tanim -o a.tanim` must not destroy a.tanim.
void protectInputs(bool on);

// Throws anim::Error when `path` does not end in `extension` (case-insensitive), e.g. a tree
// written as x.tanim would later be read as an animation: "PATH: WHAT files must end in .EXT".
void requireExtension(const std::string& path, const std::string& extension, const std::string& what);

// Writes bytes to `path` through a temporary file in the same folder and a rename; on any failure
// (or SIGINT/SIGTERM once installInterruptCleanup ran) the temporary is removed and anim::Error is
// thrown naming the path and the reason.
void writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes);
// The same for a file given in parts, written one after the other (a large file need not be
// assembled in memory first).
void writeFileAtomically(const std::string& path, std::span<const std::span<const uint8_t>> parts);

// A group of output files in one folder that appear together or not at all (an OBJ sequence): each
// write goes to a hidden staging folder next to them; commit() renames them into place. Destroyed
// (or interrupted) before commit(), it removes the staging folder, so a failure (a full disk) never
// leaves a shorter sequence that would read as a valid animation.
class AtomicFileSet {
 public:
  AtomicFileSet() = default;
  ~AtomicFileSet();
  AtomicFileSet(const AtomicFileSet&) = delete;
  AtomicFileSet& operator=(const AtomicFileSet&) = delete;
  void write(const std::string& path, std::span<const uint8_t> bytes);
  void commit();

 private:
  std::string folder_, staging_;
  std::vector<std::string> names_;
};

// Blocks SIGINT, SIGTERM and SIGHUP in the calling thread (and so in every thread it starts later)
// and starts a thread that, on one of them, removes the temporaries and staging folders in flight,
// then ends the process with that signal. Call first thing in main(), before any thread exists.
void installInterruptCleanup();

}  // namespace anim
