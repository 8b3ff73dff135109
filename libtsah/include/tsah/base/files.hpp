#pragma once
// Whole files in and out, for every reader and writer of the project: inputs that must be regular
// files of bounded size, outputs written atomically (temporary file + rename, so an interrupted run
// never leaves a half-written file), groups of outputs that appear together or not at all, and the
// signal handling that removes the temporaries in flight.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tsah/base/error.hpp"

namespace tsah {

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

// Reads a whole file; throws FileError when it is missing, not a regular file, unreadable or
// larger than maxBytes.
std::vector<uint8_t> readFile(const std::string& path, std::size_t maxBytes = std::size_t(1) << 36);
// readFile for a file the command means to rewrite (a report updated in place): not protected.
std::vector<uint8_t> readFileForUpdate(const std::string& path, std::size_t maxBytes);

// When on (the command line turns it on), every file opened as an input is remembered and the
// writers below refuse to replace one of them: `optimize a.tanim -o a.tanim` must not destroy a.tanim.
void protectInputs(bool on);

// Throws tsah::ConfigError when `path` does not end in `extension` (case-insensitive), e.g. a tree
// written as x.tanim would later be read as an animation: "PATH: WHAT files must end in .EXT".
void requireExtension(const std::string& path, const std::string& extension, const std::string& what);

// Writes bytes to `path` through a temporary file in the same folder and a rename; on any failure
// (or SIGINT/SIGTERM once installInterruptCleanup ran) the temporary is removed and tsah::Failure is
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

}  // namespace tsah
