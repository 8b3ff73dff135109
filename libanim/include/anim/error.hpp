#pragma once
// Errors raised by libanim. Every message names the file (or input) and what is wrong, so the CLI
// can print it as one line.
#include <stdexcept>
#include <string>

namespace anim {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A problem with an input file: unreadable, malformed, inconsistent with other frames.
class ImportError : public Error {
 public:
  ImportError(const std::string& file, const std::string& what)
      : Error(file + ": " + what), file_(file) {}
  const std::string& file() const noexcept { return file_; }

 private:
  std::string file_;
};

}  // namespace anim
