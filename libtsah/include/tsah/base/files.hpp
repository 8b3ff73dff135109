#pragma once
// Whole files in and out, for every reader and writer of the project: inputs that must be regular
// files of bounded size, outputs written atomically (temporary file + rename, so an interrupted run
// never leaves a half-written file), groups of outputs that appear together or not at all, and the
// signal handling that removes the temporaries in flight.
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
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
// (or one of the signals of installInterruptCleanup once it ran) the temporary is removed and tsah::Failure is
// thrown naming the path and the reason.
void writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes);
// The same for a file given in parts, written one after the other (a large file need not be
// assembled in memory first).
void writeFileAtomically(const std::string& path, std::span<const std::span<const uint8_t>> parts);

// The one way to write a group of output files that belong together and must appear together or
// not at all (a point cache and its topology OBJ, an exported tree's buffers and header, a box mesh
// and its materials, an OBJ sequence, a bench report): each write goes to a hidden staging folder
// next to them; commit() renames them into place as a unit.
// - Destroyed, failed or interrupted (SIGINT, SIGTERM, SIGHUP, SIGQUIT) before commit(), the set
//   removes its staging folder and leaves the previous files untouched: no half of a set is left.
// - commit() holds an exclusive flock(2) on the target folder, so two processes committing sets
//   into one folder take turns and the folder ends with one whole set, never a mix of both.
// - A file the commit replaces is kept aside (a hard link) until every rename succeeded; when one
//   fails, the renamed files are put back as they were.
// - The interrupt cleanup waits for a commit in progress, so a signal never stops one half-way.
// Every file of one set is in one folder.
class AtomicFileSet {
 public:
  AtomicFileSet() = default;
  ~AtomicFileSet();
  AtomicFileSet(const AtomicFileSet&) = delete;
  AtomicFileSet& operator=(const AtomicFileSet&) = delete;
  void write(const std::string& path, std::span<const uint8_t> bytes);
  void write(const std::string& path, std::span<const std::span<const uint8_t>> parts);
  void write(const std::string& path, std::string_view text);
  // The staging path at which a program the caller runs (gnuplot) creates the file `path`; it must
  // exist when commit() runs.
  std::string stage(const std::string& path);
  // Moves every file into place. $TSAH_TEST_COMMIT_DELAY_MS (tests only) makes it wait that long
  // first, so a test can interrupt a set that is staged but not committed.
  void commit();

 private:
  std::string begin(const std::string& path);  // checks `path`, returns its name in the set
  std::string folder_, staging_;
  std::vector<std::string> names_;
};

// Blocks SIGINT, SIGTERM, SIGHUP and SIGQUIT in the calling thread (and so in every thread it starts later)
// and starts a thread that, on one of them, removes the temporaries and staging folders in flight,
// then ends the process with that signal. SIGXFSZ is blocked too, so a write past the file size
// limit fails (EFBIG) and is cleaned up like a full disk. Call first thing in main(), before any
// thread exists.
void installInterruptCleanup();

}  // namespace tsah
