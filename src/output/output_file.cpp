#include "output/output_file.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <ctime>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include <tessera/check.h>

namespace tessera::detail {

namespace {

// What a non-regular file is, for the refusal's message.
const char* fileKind(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

std::string errnoText(int error) {
  return std::strerror(error);
}

ErrorCode ioCode(int error) {
  return error == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo;
}

// `role` says which directory: "output directory", "spool directory".
Result<void> checkDirectory(const std::string& dir, const std::string& what, const char* role) {
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0)
    return fail(ioCode(errno),
                fmt::format("{}: {} {} is not accessible: {}", what, role, dir, errnoText(errno)));
  if (!S_ISDIR(st.st_mode))
    return fail(ErrorCode::kIo, fmt::format("{}: {} is not a directory", what, dir));
  return {};
}

std::atomic<uint32_t> g_temp_counter{0};

// A writer killed between naming its finished file and renaming it over the target (a window
// of two system calls) leaves `TARGET.tmp-PID-N`, a complete file. The next writer of the
// target removes such names when PID is not a live process here and the name is older than
// ten minutes: a writer on another machine sharing the directory is inside that window for
// microseconds, never minutes.
void removeStaleTemporaries(const std::string& final_path) {
  namespace fs = std::filesystem;
  const fs::path target(final_path);
  const std::string prefix = target.filename().string() + ".tmp-";
  std::error_code error;
  const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
  for (fs::directory_iterator it(dir, error), end; !error && it != end; it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) continue;
    const long pid = std::strtol(name.c_str() + prefix.size(), nullptr, 10);
    struct stat info;
    if (pid <= 0 || ::lstat(it->path().c_str(), &info) != 0 || !S_ISREG(info.st_mode)) continue;
    const bool alive = ::kill(pid_t(pid), 0) == 0 || errno == EPERM;
    if (!alive && ::time(nullptr) - info.st_mtime > 600) ::unlink(it->path().c_str());
  }
}

}  // namespace

std::string directoryOf(const std::string& path) {
  std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? "." : parent.string();
}

Result<void> checkOutputPath(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return {};  // nothing there (or a dangling link) to lose
  if (S_ISREG(st.st_mode)) return {};
  return fail(ErrorCode::kInvalidArgument,
              fmt::format("{}: exists and is {}, not a regular file; refusing to replace it ({})",
                          path, fileKind(st.st_mode),
                          S_ISDIR(st.st_mode) ? "name a file inside it"
                                              : "write to a regular file and copy it there"));
}

Result<DiskSpace> diskSpaceAt(const std::string& directory) {
  struct statvfs fs {};
  struct stat st {};
  if (::statvfs(directory.c_str(), &fs) != 0 || ::stat(directory.c_str(), &st) != 0)
    return fail(ioCode(errno),
                fmt::format("{}: cannot examine the file system: {}", directory, errnoText(errno)));
  return DiskSpace{uint64_t(fs.f_bavail) * fs.f_frsize, uint64_t(st.st_dev)};
}

Result<TempFile> TempFile::openIn(const std::string& dir, const std::string& what,
                                  const std::string& fallback_path) {
  int fd = ::open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0644);
  if (fd >= 0) return TempFile(fd, what, "");
  if (errno != EOPNOTSUPP && errno != EISDIR && errno != EINVAL && errno != ENOENT)
    return fail(ErrorCode::kIo,
                fmt::format("{}: cannot create a file in {}: {}", what, dir, errnoText(errno)));
  // File systems without O_TMPFILE: a named temporary, removed by the destructor.
  fd = ::open(fallback_path.c_str(), O_CREAT | O_EXCL | O_RDWR | O_CLOEXEC, 0644);
  if (fd < 0)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot create temporary {}: {}", what,
                                            fallback_path, errnoText(errno)));
  return TempFile(fd, what, fallback_path);
}

Result<TempFile> TempFile::create(const std::string& final_path) {
  const std::string dir = directoryOf(final_path);
  TESSERA_TRY(checkDirectory(dir, final_path, "output directory"));
  // Before anything is written: a build to /dev/null should fail at once, not after an hour.
  TESSERA_TRY(checkOutputPath(final_path));
  removeStaleTemporaries(final_path);
  return openIn(dir, final_path,
                fmt::format("{}.tmp-{}-{}", final_path, ::getpid(), g_temp_counter++));
}

Result<TempFile> TempFile::createScratch(const std::string& directory, const std::string& purpose) {
  TESSERA_TRY(checkDirectory(directory, purpose, "directory"));
  const std::string fallback = (std::filesystem::path(directory) /
                                fmt::format(".tessera-scratch-{}-{}", ::getpid(), g_temp_counter++))
                                   .string();
  TESSERA_ASSIGN_OR_RETURN(TempFile file, openIn(directory, purpose, fallback));
  file.scratch_ = true;
  return file;
}

TempFile::TempFile(TempFile&& other) noexcept
    : fd_(other.fd_),
      final_path_(std::move(other.final_path_)),
      temp_path_(std::move(other.temp_path_)),
      committed_(other.committed_),
      scratch_(other.scratch_) {
  other.fd_ = -1;
  other.temp_path_.clear();
}

TempFile::~TempFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !temp_path_.empty()) ::unlink(temp_path_.c_str());
}

Result<void> TempFile::pwrite(uint64_t offset_bytes, std::span<const uint8_t> bytes) const {
  size_t done = 0;
  while (done < bytes.size()) {
    ssize_t n = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, off_t(offset_bytes + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      return fail(ErrorCode::kIo, fmt::format("{}: write at offset {} failed: {}", final_path_,
                                              offset_bytes + done, errnoText(errno)));
    }
    done += size_t(n);
  }
  return {};
}

Result<void> TempFile::pread(uint64_t offset_bytes, std::span<uint8_t> out) const {
  size_t done = 0;
  while (done < out.size()) {
    ssize_t n = ::pread(fd_, out.data() + done, out.size() - done, off_t(offset_bytes + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      return fail(ErrorCode::kIo,
                  fmt::format("{}: reading back the temporary at {} failed: {}", final_path_,
                              offset_bytes + done, n < 0 ? errnoText(errno) : "end of file"));
    done += size_t(n);
  }
  return {};
}

void TempFile::startWriteback(uint64_t offset_bytes, uint64_t bytes) const {
  if (scratch_) return;  // never kept: writing it to the disk would be wasted
  (void)::sync_file_range(fd_, off_t(offset_bytes), off_t(bytes), SYNC_FILE_RANGE_WRITE);
}

Result<void> TempFile::commit() {
  TESSERA_CHECK(!scratch_) << final_path_ << ": a scratch file is never committed";
  if (::fsync(fd_) != 0)
    return fail(ErrorCode::kIo, fmt::format("{}: fsync failed: {}", final_path_, errnoText(errno)));
  // Again: a FIFO or device node made at the path while the file was written is not replaced
  // either (a narrower race than none: rename itself cannot be told to spare one).
  TESSERA_TRY(checkOutputPath(final_path_));
  std::string named = temp_path_;
  if (named.empty()) {
    // Give the anonymous file a unique name beside the target, then rename it over the target:
    // linkat cannot replace an existing file, rename can, atomically.
    named = fmt::format("{}.tmp-{}-{}", final_path_, ::getpid(), g_temp_counter++);
    std::string proc = fmt::format("/proc/self/fd/{}", fd_);
    if (::linkat(AT_FDCWD, proc.c_str(), AT_FDCWD, named.c_str(), AT_SYMLINK_FOLLOW) != 0)
      return fail(ErrorCode::kIo, fmt::format("{}: cannot name the finished file: {}", final_path_,
                                              errnoText(errno)));
  }
  if (::rename(named.c_str(), final_path_.c_str()) != 0) {
    int error = errno;
    ::unlink(named.c_str());
    return fail(ErrorCode::kIo,
                fmt::format("{}: cannot rename into place: {}", final_path_, errnoText(error)));
  }
  committed_ = true;
  temp_path_.clear();
  int dir_fd = ::open(directoryOf(final_path_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd >= 0) {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
  return {};
}

Result<void> writeFileAtomically(const std::string& path, std::span<const uint8_t> bytes) {
  TESSERA_ASSIGN_OR_RETURN(TempFile file, TempFile::create(path));
  TESSERA_TRY(file.pwrite(0, bytes));
  return file.commit();
}

}  // namespace tessera::detail
