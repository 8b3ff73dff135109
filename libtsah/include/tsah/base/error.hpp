#pragma once
// The toolkit's exceptions: one vocabulary for libanim, libtsah, the GPU runtime, the command line
// and the Python module. Every message is one line that names the file or the setting at fault and
// says what is wrong, so a caller can print it as it is.
//
// Which one to throw is decided by whose mistake it is, never by the file that throws:
//   ConfigError  the caller asked for something invalid: an option out of range, an unknown name,
//                a setting that contradicts another, a call the object cannot serve. The caller
//                fixes the call. (Python: tsah.ConfigError, also a ValueError. `tsah` exits 2 for
//                the mistakes its own option checks find, tsah::cli::UsageError, and 1 for all
//                others, whatever the library throws.)
//   DataError    the data handed over is unusable: an animation with NaN coordinates, a tree that
//                is not a tree, a tree built for another animation. FileError is the same for data
//                read from a file, and names it. (Python: tsah.DataError /
//                tsah.FileError, also ValueErrors.)
//   Failure      the request and the data were fine, but the work failed: a write error or a full
//                disk, not enough memory, a GPU error, an interruption. (Python:
//                tsah.Failure, also a RuntimeError.)
// Error itself is the common base (catch it to handle all three); nothing throws a bare Error.
// Internal invariants are not exceptions: they are TSAH_ASSERT (tsah/base/assert.hpp).
#include <cstdio>
#include <stdexcept>
#include <string>
#include <string_view>

namespace tsah {

// `text` with every control character written as \xHH: a name taken from a file or the command line
// (a file name, an object name) cannot break a one-line message or send escapes to a terminal.
inline std::string printable(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte >= 0x20 && byte != 0x7f) {
      out += c;
      continue;
    }
    char escaped[5];
    std::snprintf(escaped, sizeof escaped, "\\x%02x", byte);
    out += escaped;
  }
  return out;
}

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class ConfigError : public Error {
 public:
  using Error::Error;
};

class DataError : public Error {
 public:
  using Error::Error;
};

// Bad data read from a file: the message is "FILE: what is wrong".
class FileError : public DataError {
 public:
  FileError(const std::string& file, const std::string& what) : DataError(printable(file) + ": " + what), file_(file) {}
  const std::string& file() const noexcept { return file_; }

 private:
  std::string file_;
};

class Failure : public Error {
 public:
  using Error::Error;
};

// The caller asked a long computation to stop (a cancel check it handed over returned true, e.g.
// Ctrl-C in Python, which raises KeyboardInterrupt for it). Nothing it would have produced exists.
class Cancelled : public Failure {
 public:
  using Failure::Failure;
};

}  // namespace tsah
