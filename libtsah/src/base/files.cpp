// Opening inputs and writing outputs safely (declared in tsah/base/files.hpp): regular files only,
// inputs protected from being overwritten, atomic single and multi-file writes, and removal of the
// temporaries in flight when the process is interrupted.
#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <set>
#include <thread>

#include "tsah/base/files.hpp"

namespace tsah {

namespace fs = std::filesystem;

namespace {

// What the process must remember across calls: inputs not to overwrite, temporaries to remove.
struct FileRegistry {
  std::mutex mutex;
  bool protectInputs = false;
  std::set<std::pair<dev_t, ino_t>> inputs;
  std::set<std::string> inFlight;  // temporary files and staging folders
};
FileRegistry& registry() {
  static FileRegistry r;
  return r;
}

// Keeps a temporary path in the interrupt cleanup list for its lifetime.
class InFlight {
 public:
  explicit InFlight(std::string path) : path_(std::move(path)) {
    std::lock_guard lock(registry().mutex);
    registry().inFlight.insert(path_);
  }
  ~InFlight() {
    std::lock_guard lock(registry().mutex);
    registry().inFlight.erase(path_);
  }
  InFlight(const InFlight&) = delete;
  InFlight& operator=(const InFlight&) = delete;

 private:
  std::string path_;
};

std::string errnoText(int e) { return std::strerror(e); }

std::string notRegular(mode_t mode) {
  if (S_ISDIR(mode)) return "is a directory, not a file";
  if (S_ISFIFO(mode)) return "is a FIFO (named pipe), not a regular file";
  if (S_ISCHR(mode)) return "is a character device, not a regular file";
  if (S_ISBLK(mode)) return "is a block device, not a regular file";
  if (S_ISSOCK(mode)) return "is a socket, not a regular file";
  return "is not a regular file";
}

std::string folderOf(const fs::path& p) { return p.parent_path().empty() ? "." : p.parent_path().string(); }

// Why a file could not be created in `folder`, in words a user can act on.
std::string createFailure(int e, const std::string& folder) {
  if (e == ENOENT) return "folder " + folder + " does not exist";
  return "cannot create a file in " + folder + ": " + errnoText(e);
}

// Refuses to replace a file this process read as an input (same device and inode, so any spelling
// of the path, hard links included, is caught).
void refuseOverwritingInput(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return;
  if (S_ISDIR(st.st_mode)) throw ConfigError(path + ": is a folder; expected a file name");
  std::lock_guard lock(registry().mutex);
  if (registry().protectInputs && registry().inputs.count({st.st_dev, st.st_ino}))
    throw ConfigError(path + ": is also an input of this command; refusing to overwrite it (choose another output)");
}

// A temporary name next to `target` that stays within NAME_MAX however long the target's name is.
fs::path temporarySibling(const fs::path& target, const char* kind) {
  static std::atomic<unsigned> counter{0};
  std::string name = target.filename().string();
  const std::string suffix = std::string(".") + kind + "." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  constexpr std::size_t kNameMax = 255;
  if (1 + name.size() + suffix.size() > kNameMax) name.resize(kNameMax - 1 - suffix.size());
  return target.parent_path() / ("." + name + suffix);
}

// Creates `file` and writes all bytes; on failure removes it and throws naming `path` (the output
// the user asked for) and the reason.
void writeNewFile(const fs::path& file, const std::string& path, std::span<const std::span<const uint8_t>> parts) {
  const int fd = ::open(file.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) {
    const int e = errno;
    if (e == ENAMETOOLONG) throw ConfigError(path + ": file name too long");
    throw Failure(path + ": " + createFailure(e, folderOf(fs::path(path))));
  }
  std::size_t done = 0, total = 0;
  for (const auto& bytes : parts) total += bytes.size();
  int error = 0;
  for (const auto& bytes : parts) {
    std::size_t written = 0;
    while (error == 0 && written < bytes.size()) {
      const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        error = n < 0 ? errno : EIO;
        break;
      }
      written += std::size_t(n);
      done += std::size_t(n);
    }
  }
  if (::close(fd) != 0 && error == 0) error = errno;
  if (error != 0) {
    ::unlink(file.c_str());
    throw Failure(path + ": write failed after " + std::to_string(done) + " of " + std::to_string(total) +
                " bytes: " + errnoText(error));
  }
}

void removeInFlight() {
  std::lock_guard lock(registry().mutex);
  for (const std::string& p : registry().inFlight) {
    std::error_code ignore;
    fs::remove_all(p, ignore);
  }
  registry().inFlight.clear();
}

}  // namespace

InputFile::InputFile(const std::string& path, bool protect) {
  // O_NONBLOCK: opening a FIFO without a writer would otherwise block before fstat can refuse it.
  fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) {
    const int e = errno;
    throw FileError(path, e == ENOENT ? std::string("no such file") : "cannot open: " + errnoText(e));
  }
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    const std::string what = S_ISREG(st.st_mode) ? "cannot stat: " + errnoText(errno) : notRegular(st.st_mode);
    ::close(fd_);
    throw FileError(path, what);
  }
  ::fcntl(fd_, F_SETFL, ::fcntl(fd_, F_GETFL) & ~O_NONBLOCK);
  size_ = std::size_t(st.st_size);
  std::lock_guard lock(registry().mutex);
  if (protect && registry().protectInputs) registry().inputs.insert({st.st_dev, st.st_ino});
}

InputFile::~InputFile() {
  if (fd_ >= 0) ::close(fd_);
}

void checkInputFile(const std::string& path) { InputFile check(path); }

namespace {
std::vector<uint8_t> readWhole(const std::string& path, std::size_t maxBytes, bool protect) {
  InputFile in(path, protect);
  if (in.size() > maxBytes)
    throw FileError(path, "file is " + std::to_string(in.size()) + " bytes, more than the limit of " +
                                std::to_string(maxBytes));
  std::vector<uint8_t> bytes(in.size());
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::read(in.fd(), bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw FileError(path, "read error: " + errnoText(errno));
    if (n == 0) throw FileError(path, "file shrank while being read");
    done += std::size_t(n);
  }
  return bytes;
}
}  // namespace

std::vector<uint8_t> readFile(const std::string& path, std::size_t maxBytes) { return readWhole(path, maxBytes, true); }

std::vector<uint8_t> readFileForUpdate(const std::string& path, std::size_t maxBytes) {
  return readWhole(path, maxBytes, false);
}

void protectInputs(bool on) {
  std::lock_guard lock(registry().mutex);
  registry().protectInputs = on;
}

void requireExtension(const std::string& path, const std::string& extension, const std::string& what) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext != extension) throw ConfigError(path + ": " + what + " files must end in " + extension);
}

void writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes) {
  const std::span<const uint8_t> whole[] = {bytes};
  writeFileAtomically(path, std::span<const std::span<const uint8_t>>(whole));
}

void writeFileAtomically(const std::string& path, std::span<const std::span<const uint8_t>> parts) {
  refuseOverwritingInput(path);
  const fs::path target(path);
  if (target.filename().string().size() > 255) throw ConfigError(path + ": file name too long");
  const fs::path tmp = temporarySibling(target, "tmp");
  InFlight cleanup(tmp.string());
  writeNewFile(tmp, path, parts);
  if (::rename(tmp.c_str(), target.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    throw Failure(path + ": cannot rename the temporary file into place: " + errnoText(e));
  }
}

AtomicFileSet::~AtomicFileSet() {
  if (staging_.empty()) return;
  std::error_code ignore;
  fs::remove_all(staging_, ignore);
  std::lock_guard lock(registry().mutex);
  registry().inFlight.erase(staging_);
}

std::string AtomicFileSet::begin(const std::string& path) {
  const fs::path target(path);
  const std::string folder = folderOf(target);
  if (staging_.empty()) {
    const fs::path staging = temporarySibling(fs::path(folder) / "tsah-staging", "dir");
    {
      std::lock_guard lock(registry().mutex);
      registry().inFlight.insert(staging.string());
    }
    staging_ = staging.string();
    folder_ = folder;
    if (::mkdir(staging.c_str(), 0777) != 0) {
      const int e = errno;
      throw Failure(path + ": " + createFailure(e, folder));
    }
  } else if (folder != folder_) {
    throw ConfigError(path + ": every file of one output set must be in one folder (" + folder_ + ")");
  }
  refuseOverwritingInput(path);
  const std::string name = target.filename().string();
  if (name.size() > 255) throw ConfigError(path + ": file name too long");
  if (std::find(names_.begin(), names_.end(), name) != names_.end())
    throw ConfigError(path + ": written twice in one output set");
  return name;
}

void AtomicFileSet::write(const std::string& path, std::span<const std::span<const uint8_t>> parts) {
  const std::string name = begin(path);
  writeNewFile(fs::path(staging_) / name, path, parts);
  names_.push_back(name);
}

void AtomicFileSet::write(const std::string& path, std::span<const uint8_t> bytes) {
  const std::span<const uint8_t> whole[] = {bytes};
  write(path, std::span<const std::span<const uint8_t>>(whole));
}

void AtomicFileSet::write(const std::string& path, std::string_view text) {
  write(path, std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

std::string AtomicFileSet::stage(const std::string& path) {
  const std::string name = begin(path);
  names_.push_back(name);
  return (fs::path(staging_) / name).string();
}

namespace {

// An exclusive flock(2) on a folder for the lifetime of the object: commits into one folder take
// turns. Where the file system has no flock (some network mounts) the commit goes on unlocked.
class FolderLock {
 public:
  explicit FolderLock(const std::string& folder) {
    fd_ = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd_ < 0) throw Failure(folder + ": cannot open the folder to lock it: " + errnoText(errno));
    while (::flock(fd_, LOCK_EX) != 0) {
      if (errno == EINTR) continue;
      if (errno == ENOLCK || errno == EOPNOTSUPP || errno == EINVAL) break;
      const int e = errno;
      ::close(fd_);
      throw Failure(folder + ": cannot lock the folder: " + errnoText(e));
    }
  }
  ~FolderLock() { ::close(fd_); }  // closing releases the lock
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  int fd_ = -1;
};

// $TSAH_TEST_COMMIT_DELAY_MS: the test hook of AtomicFileSet::commit.
void testCommitDelay() {
  const char* text = std::getenv("TSAH_TEST_COMMIT_DELAY_MS");
  if (text && *text) std::this_thread::sleep_for(std::chrono::milliseconds(std::strtoul(text, nullptr, 10)));
}

}  // namespace

void AtomicFileSet::commit() {
  if (names_.empty()) return;
  testCommitDelay();
  const FolderLock folderLock(folder_);
  // Under the registry's lock: the interrupt cleanup waits until the set is wholly in place (or
  // wholly rolled back) before it removes the staging folder and ends the process.
  std::lock_guard lock(registry().mutex);
  // The files a rename replaces stay reachable as hard links in the staging folder until the end.
  struct Placed {
    fs::path target, kept;
  };
  std::vector<Placed> placed;
  for (std::size_t i = 0; i < names_.size(); ++i) {
    const fs::path from = fs::path(staging_) / names_[i], to = fs::path(folder_) / names_[i];
    const fs::path kept = fs::path(staging_) / (".kept." + std::to_string(i));
    const bool hadOld = ::link(to.c_str(), kept.c_str()) == 0;
    if (::rename(from.c_str(), to.c_str()) != 0) {
      const int e = errno;
      // Put back what this commit replaced and remove what it added: the set stays as it was.
      for (const Placed& p : placed) {
        if (!p.kept.empty()) ::rename(p.kept.c_str(), p.target.c_str());
        else ::unlink(p.target.c_str());
      }
      throw Failure(to.string() + ": cannot rename the staged file into place: " + errnoText(e));
    }
    placed.push_back({to, hadOld ? kept : fs::path()});
  }
  std::error_code ignore;
  fs::remove_all(staging_, ignore);
  registry().inFlight.erase(staging_);
  staging_.clear();
  names_.clear();
}

void installInterruptCleanup() {
  sigset_t signals;
  sigemptyset(&signals);
  for (int s : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) sigaddset(&signals, s);
  // SIGXFSZ blocked (not waited for): a write past the file size limit then fails with EFBIG and is
  // reported and cleaned up like a full disk, instead of killing the process half-way through a set.
  sigset_t blocked = signals;
  sigaddset(&blocked, SIGXFSZ);
  pthread_sigmask(SIG_BLOCK, &blocked, nullptr);
  // A normal thread (not a signal handler) waits for them, so the cleanup may lock and allocate.
  std::thread([signals] {
    int sig = 0;
    while (sigwait(&signals, &sig) != 0) {
    }
    removeInFlight();
    ::signal(sig, SIG_DFL);
    sigset_t one;
    sigemptyset(&one);
    sigaddset(&one, sig);
    pthread_sigmask(SIG_UNBLOCK, &one, nullptr);
    ::raise(sig);
    ::_exit(128 + sig);
  }).detach();
}

}  // namespace tsah
