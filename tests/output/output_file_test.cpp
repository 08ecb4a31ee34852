// The builder's atomic output: nothing is visible until commit, a discarded file leaves
// nothing behind, and commit replaces a previous file whole.
#include "output/output_file.h"

#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "support/test_images.h"

namespace tessera::detail {
namespace {

std::vector<std::string> listDir(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::span<const uint8_t> asBytes(const std::string& text) {
  return {reinterpret_cast<const uint8_t*>(text.data()), text.size()};
}

TEST(TempFile, NothingIsVisibleBeforeCommitAndTheFileAppearsAfter) {
  std::string dir = test::testTempDir();
  std::string path = dir + "out.tess";
  auto file = TempFile::create(path);
  ASSERT_TRUE(file) << file.error().message;
  ASSERT_TRUE(file->pwrite(6, asBytes("world")));
  ASSERT_TRUE(file->pwrite(0, asBytes("hello ")));
  EXPECT_FALSE(std::filesystem::exists(path));
  std::vector<uint8_t> back(11);
  ASSERT_TRUE(file->pread(0, back));
  EXPECT_EQ(std::string(back.begin(), back.end()), "hello world");
  ASSERT_TRUE(file->commit());
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "hello world");
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

TEST(TempFile, ADiscardedFileLeavesNothingBehind) {
  std::string dir = test::testTempDir();
  {
    auto file = TempFile::create(dir + "out.tess");
    ASSERT_TRUE(file);
    ASSERT_TRUE(file->pwrite(0, asBytes("partial")));
  }
  EXPECT_TRUE(listDir(dir).empty());
}

TEST(TempFile, CommitReplacesAPreviousFileWhole) {
  std::string dir = test::testTempDir();
  std::string path = dir + "out.tess";
  ASSERT_TRUE(test::writeFileBytes(path, std::vector<uint8_t>(1000, 'x')));
  auto file = TempFile::create(path);
  ASSERT_TRUE(file);
  ASSERT_TRUE(file->pwrite(0, asBytes("new")));
  EXPECT_EQ(test::readFileBytes(path).size(), 1000u);  // untouched until commit
  ASSERT_TRUE(file->commit());
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "new");
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

// A writer killed between naming and renaming its finished file leaves OUT.tmp-PID-N; the next
// writer removes it once the process is gone and the file is ten minutes old, and keeps
// names of live processes, fresh names and other files.
TEST(TempFile, StaleTemporariesOfDeadWritersAreRemovedByTheNextWriter) {
  std::string dir = test::testTempDir();
  const pid_t dead = fork();
  if (dead == 0) _exit(0);
  ASSERT_GT(dead, 0);
  waitpid(dead, nullptr, 0);  // reaped: the pid names no process now
  const auto make = [&](const std::string& name, bool old) {
    ASSERT_TRUE(test::writeFileBytes(dir + name, std::vector<uint8_t>(10, 'x')));
    if (!old) return;
    const timespec times[2] = {{::time(nullptr) - 3600, 0}, {::time(nullptr) - 3600, 0}};
    ASSERT_EQ(utimensat(AT_FDCWD, (dir + name).c_str(), times, 0), 0);
  };
  const std::string stale = fmt::format("out.tess.tmp-{}-3", dead);
  const std::string fresh = fmt::format("out.tess.tmp-{}-4", dead);
  const std::string live = fmt::format("out.tess.tmp-{}-5", getpid());
  const std::string other = fmt::format("other.tess.tmp-{}-6", dead);
  make(stale, true);
  make(fresh, false);
  make(live, true);
  make(other, true);
  auto file = TempFile::create(dir + "out.tess");
  ASSERT_TRUE(file) << file.error().message;
  ASSERT_TRUE(file->commit());
  std::vector<std::string> expected = {fresh, live, other, "out.tess"};
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(listDir(dir), expected);
}

TEST(TempFile, ADiscardedFileLeavesAPreviousFileUntouched) {
  std::string dir = test::testTempDir();
  std::string path = dir + "out.tess";
  ASSERT_TRUE(test::writeFileBytes(path, std::vector<uint8_t>(10, 'p')));
  {
    auto file = TempFile::create(path);
    ASSERT_TRUE(file);
    ASSERT_TRUE(file->pwrite(0, asBytes("replacement")));
  }
  EXPECT_EQ(test::readFileBytes(path), std::vector<uint8_t>(10, 'p'));
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

TEST(TempFile, AMovedFileIsOwnedOnce) {
  std::string dir = test::testTempDir();
  auto file = TempFile::create(dir + "out.tess");
  ASSERT_TRUE(file);
  {
    TempFile moved(std::move(*file));
    ASSERT_TRUE(moved.pwrite(0, asBytes("abc")));
    ASSERT_TRUE(moved.commit());
  }
  // The moved-from object's destructor must neither close nor remove anything.
  EXPECT_EQ(test::readFileBytes(dir + "out.tess").size(), 3u);
}

TEST(TempFile, AMissingDirectoryIsNotFoundNamingThePath) {
  std::string path = test::testTempDir() + "no/such/dir/out.tess";
  auto file = TempFile::create(path);
  ASSERT_FALSE(file);
  EXPECT_EQ(file.error().code, ErrorCode::kNotFound);
  EXPECT_NE(file.error().message.find(path), std::string::npos) << file.error().message;
}

TEST(TempFile, AParentThatIsAFileIsRejected) {
  std::string dir = test::testTempDir();
  ASSERT_TRUE(test::writeFileBytes(dir + "file", {1, 2, 3}));
  auto file = TempFile::create(dir + "file/out.tess");
  ASSERT_FALSE(file);
  EXPECT_NE(file.error().message.find("file/out.tess"), std::string::npos) << file.error().message;
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"file"});
}

TEST(TempFile, ReadingPastTheWrittenEndFails) {
  auto file = TempFile::create(test::testTempDir() + "out.tess");
  ASSERT_TRUE(file);
  ASSERT_TRUE(file->pwrite(0, asBytes("abc")));
  std::vector<uint8_t> out(4);
  auto read = file->pread(0, out);
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("out.tess"), std::string::npos);
}

TEST(TempFile, ARelativePathUsesTheCurrentDirectory) {
  std::string dir = test::testTempDir();
  std::filesystem::path previous = std::filesystem::current_path();
  std::filesystem::current_path(dir);
  {
    auto file = TempFile::create("relative.tess");
    EXPECT_TRUE(file) << file.error().message;
    if (file) {
      EXPECT_TRUE(file->pwrite(0, asBytes("r")));
      EXPECT_TRUE(file->commit());
    }
  }
  std::filesystem::current_path(previous);
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"relative.tess"});
}

// ---- What is at the output path -------------------------------------------------------------

/// The file type of `path` (not following a link), or 0 when nothing is there.
mode_t fileType(const std::string& path) {
  struct stat st {};
  return ::lstat(path.c_str(), &st) == 0 ? st.st_mode & S_IFMT : 0;
}

TEST(TempFile, AFifoAtThePathIsRefusedAndKept) {
  const std::string dir = test::testTempDir();
  const std::string path = dir + "pipe";
  ASSERT_EQ(::mkfifo(path.c_str(), 0644), 0);
  auto file = TempFile::create(path);
  ASSERT_FALSE(file);
  EXPECT_EQ(file.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(file.error().message.find(path + ": exists and is a FIFO (named pipe), not a regular "
                                             "file; refusing to replace it"),
            std::string::npos)
      << file.error().message;
  EXPECT_EQ(fileType(path), mode_t(S_IFIFO));
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"pipe"});
}

TEST(TempFile, ADeviceNodeAtThePathIsRefusedAndKept) {
  const std::string dir = test::testTempDir();
  const std::string path = dir + "null";
  // A private copy of /dev/null (1, 3): the real one must never be at stake in a test.
  if (::mknod(path.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0)
    GTEST_SKIP() << "cannot make a device node (needs root): " << std::strerror(errno);
  auto file = TempFile::create(path);
  ASSERT_FALSE(file);
  EXPECT_NE(file.error().message.find("is a character device"), std::string::npos)
      << file.error().message;
  EXPECT_EQ(fileType(path), mode_t(S_IFCHR));
  EXPECT_EQ(writeFileAtomically(path, asBytes("data")).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(fileType(path), mode_t(S_IFCHR));
}

TEST(TempFile, DevNullIsRefused) {
  // Read-only: the check never writes, and nothing is created when it refuses.
  Result<void> checked = checkOutputPath("/dev/null");
  ASSERT_FALSE(checked);
  EXPECT_NE(checked.error().message.find("/dev/null: exists and is a character device"),
            std::string::npos)
      << checked.error().message;
}

TEST(TempFile, ADirectoryASocketAndALinkToAFifoAreRefused) {
  const std::string dir = test::testTempDir();
  std::filesystem::create_directory(dir + "folder");
  auto folder = TempFile::create(dir + "folder");
  ASSERT_FALSE(folder);
  EXPECT_NE(folder.error().message.find("is a directory, not a regular file"), std::string::npos)
      << folder.error().message;

  const std::string socket_path = dir + "sock";
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  ASSERT_LT(socket_path.size(), sizeof(address.sun_path));
  std::strcpy(address.sun_path, socket_path.c_str());
  ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&address), sizeof(address)), 0);
  auto socket_file = TempFile::create(socket_path);
  ::close(fd);
  ASSERT_FALSE(socket_file);
  EXPECT_NE(socket_file.error().message.find("is a socket"), std::string::npos);
  EXPECT_EQ(fileType(socket_path), mode_t(S_IFSOCK));

  ASSERT_EQ(::mkfifo((dir + "pipe").c_str(), 0644), 0);
  std::filesystem::create_symlink(dir + "pipe", dir + "link");
  auto linked = TempFile::create(dir + "link");
  ASSERT_FALSE(linked);
  EXPECT_NE(linked.error().message.find("FIFO"), std::string::npos) << linked.error().message;
  EXPECT_EQ(fileType(dir + "link"), mode_t(S_IFLNK));
}

TEST(TempFile, AFifoMadeWhileTheFileIsWrittenIsNotReplacedAtCommit) {
  const std::string dir = test::testTempDir();
  const std::string path = dir + "out.tess";
  Result<void> committed;
  {
    auto file = TempFile::create(path);
    ASSERT_TRUE(file);
    ASSERT_TRUE(file->pwrite(0, asBytes("archive")));
    ASSERT_EQ(::mkfifo(path.c_str(), 0644), 0);
    committed = file->commit();
  }
  ASSERT_FALSE(committed);
  EXPECT_NE(committed.error().message.find("FIFO"), std::string::npos);
  EXPECT_EQ(fileType(path), mode_t(S_IFIFO));
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

TEST(TempFile, ARegularFileAndAMissingPathAreAccepted) {
  const std::string dir = test::testTempDir();
  EXPECT_TRUE(checkOutputPath(dir + "missing.tess"));
  ASSERT_TRUE(test::writeFileBytes(dir + "old.tess", {1}));
  EXPECT_TRUE(checkOutputPath(dir + "old.tess"));
  std::filesystem::create_symlink(dir + "gone", dir + "dangling");
  EXPECT_TRUE(checkOutputPath(dir + "dangling"));
}

// ---- Scratch files and free space ------------------------------------------------------------

TEST(TempFile, AScratchFileLivesInItsDirectoryAndLeavesNothing) {
  const std::string dir = test::testTempDir();
  std::filesystem::create_directory(dir + "spool");
  {
    auto scratch = TempFile::createScratch(dir + "spool", "out.tess: spool");
    ASSERT_TRUE(scratch) << scratch.error().message;
    ASSERT_TRUE(scratch->pwrite(0, asBytes("tiles")));
    std::vector<uint8_t> back(5);
    ASSERT_TRUE(scratch->pread(0, back));
    EXPECT_EQ(std::string(back.begin(), back.end()), "tiles");
  }
  EXPECT_TRUE(listDir(dir + "spool").empty());
  auto missing = TempFile::createScratch(dir + "nowhere", "out.tess: spool");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("out.tess: spool: directory " + dir + "nowhere"),
            std::string::npos)
      << missing.error().message;
}

TEST(DiskSpace, ReportsTheFreeBytesAndTheFileSystem) {
  const std::string dir = test::testTempDir();
  std::filesystem::create_directory(dir + "sub");
  auto here = diskSpaceAt(dir);
  ASSERT_TRUE(here) << here.error().message;
  EXPECT_GT(here->available_bytes, 0u);
  auto sub = diskSpaceAt(dir + "sub");
  ASSERT_TRUE(sub);
  EXPECT_EQ(sub->device, here->device);
  auto missing = diskSpaceAt(dir + "missing");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find(dir + "missing"), std::string::npos);
  EXPECT_EQ(directoryOf("out.tess"), ".");
  EXPECT_EQ(directoryOf("/a/b/out.tess"), "/a/b");
}

}  // namespace
}  // namespace tessera::detail
