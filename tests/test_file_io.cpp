// Inputs and outputs (anim/binary_io.hpp): regular files only, protected inputs, atomic file sets,
// and removal of temporaries when the process is interrupted.
#include <gtest/gtest.h>
#include <signal.h>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "tsah/base/files.hpp"
#include "tsah/base/error.hpp"
#include "test_support.hpp"

namespace {
namespace fs = std::filesystem;

std::span<const uint8_t> text(const std::string& s) { return {reinterpret_cast<const uint8_t*>(s.data()), s.size()}; }

std::size_t entries(const fs::path& dir) {
  return std::size_t(std::distance(fs::directory_iterator(dir), fs::directory_iterator()));
}

fs::path freshDir(const std::string& name) {
  const fs::path dir = tsah::test::scratchDir() / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}
}  // namespace

TEST(FileIo, RefusesFifoDirectoryAndDevice) {
  const fs::path dir = freshDir("fileio-kinds");
  const std::string fifo = (dir / "pipe").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_TRUE(tsah::test::throwsFileError([&] { tsah::readFile(fifo); }, {"is a FIFO"}));  // must not block
  EXPECT_THROW(tsah::readFile(dir.string()), tsah::FileError);
  EXPECT_THROW(tsah::checkInputFile("/dev/null"), tsah::FileError);
}

TEST(FileIo, FileSetAppearsTogetherOrNotAtAll) {
  const fs::path dir = freshDir("fileio-set");
  {
    tsah::AtomicFileSet set;
    set.write((dir / "a.obj").string(), text("a"));
    set.write((dir / "b.obj").string(), text("b"));
    EXPECT_FALSE(fs::exists(dir / "a.obj"));  // staged, not yet visible
    // A third write fails (name too long): the set is abandoned.
    EXPECT_THROW(set.write((dir / std::string(300, 'x')).string(), text("c")), tsah::Error);
  }
  EXPECT_EQ(entries(dir), 0u) << "an abandoned set leaves nothing behind";
  tsah::AtomicFileSet set;
  set.write((dir / "a.obj").string(), text("a"));
  set.write((dir / "b.obj").string(), text("b"));
  set.commit();
  EXPECT_TRUE(fs::exists(dir / "a.obj"));
  EXPECT_TRUE(fs::exists(dir / "b.obj"));
  EXPECT_EQ(entries(dir), 2u) << "the staging folder is gone";
}

TEST(FileIo, ProtectedInputIsNotOverwritten) {
  const fs::path dir = freshDir("fileio-protect");
  const std::string in = (dir / "in.bin").string();
  tsah::writeFileAtomically(in, text("input"));
  tsah::protectInputs(true);
  (void)tsah::readFile(in);
  EXPECT_THROW(tsah::writeFileAtomically((dir / "." / "in.bin").string(), text("output")), tsah::Error);
  tsah::protectInputs(false);
  EXPECT_EQ(tsah::readFile(in).size(), 5u);
}

TEST(FileIo, LongLegalNameGetsAShortTemporary) {
  const fs::path dir = freshDir("fileio-long");
  const std::string name = std::string(250, 'n');  // legal; NAME.tmp.PID would not be
  tsah::writeFileAtomically((dir / name).string(), text("x"));
  EXPECT_TRUE(fs::exists(dir / name));
  EXPECT_EQ(entries(dir), 1u);
}

TEST(FileIo, InterruptRemovesStagedFiles) {
  const fs::path dir = freshDir("fileio-signal");
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    tsah::installInterruptCleanup();
    tsah::AtomicFileSet set;
    set.write((dir / "f_0001.obj").string(), text("v 0 0 0\n"));
    ::kill(::getpid(), SIGTERM);  // delivered to the cleanup thread, which ends the process
    for (;;) ::pause();
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << "status " << status;
  EXPECT_EQ(entries(dir), 0u) << "the staging folder was removed";
}

namespace {
std::string contents(const fs::path& file) {
  const std::vector<uint8_t> bytes = tsah::readFile(file.string());
  return {bytes.begin(), bytes.end()};
}
}  // namespace

TEST(FileIo, FailedCommitLeavesThePreviousSet) {
  const fs::path dir = freshDir("fileio-rollback");
  tsah::writeFileAtomically((dir / "x.pc2").string(), text("old cache"));
  tsah::writeFileAtomically((dir / "x.obj").string(), text("old mesh"));
  {
    tsah::AtomicFileSet set;
    set.write((dir / "x.pc2").string(), text("new cache"));
    set.write((dir / "y.obj").string(), text("new mesh"));
    fs::create_directory(dir / "y.obj");  // appears after staging: the second rename fails
    EXPECT_THROW(set.commit(), tsah::Failure);
  }
  EXPECT_EQ(contents(dir / "x.pc2"), "old cache") << "the replaced file is put back";
  EXPECT_TRUE(fs::is_directory(dir / "y.obj"));
  EXPECT_EQ(entries(dir), 3u) << "nothing else is left (no staging folder)";
}

TEST(FileIo, CommitWaitsForTheFolderLock) {
  const fs::path dir = freshDir("fileio-lock");
  // Another writer holds the folder: a commit must wait for it instead of mixing its files in.
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(fd);
    tsah::AtomicFileSet set;
    set.write((dir / "x.pc2").string(), text("cache"));
    set.write((dir / "x.obj").string(), text("mesh"));
    set.commit();
    ::_exit(0);
  }
  ::usleep(300000);
  EXPECT_FALSE(fs::exists(dir / "x.pc2")) << "committed while another writer held the folder";
  ::flock(fd, LOCK_UN);
  ::close(fd);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  EXPECT_TRUE(fs::exists(dir / "x.pc2"));
  EXPECT_TRUE(fs::exists(dir / "x.obj"));
}

TEST(FileIo, StagedPathIsCommittedWithTheSet) {
  const fs::path dir = freshDir("fileio-stage");
  tsah::AtomicFileSet set;
  set.write((dir / "plot.gp").string(), text("plot"));
  const std::string png = set.stage((dir / "plot.png").string());
  tsah::writeFileAtomically(png, text("png"));  // what an external program would write
  EXPECT_FALSE(fs::exists(dir / "plot.png"));
  set.commit();
  EXPECT_EQ(contents(dir / "plot.png"), "png");
  EXPECT_EQ(entries(dir), 2u);
}
