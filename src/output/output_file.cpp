#include "output/output_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

namespace tessera::detail {

namespace {

std::string directoryOf(const std::string& path) {
  std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? "." : parent.string();
}

std::string errnoText(int error) {
  return std::strerror(error);
}

ErrorCode ioCode(int error) {
  return error == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo;
}

}  // namespace

Result<TempFile> TempFile::create(const std::string& final_path) {
  std::string dir = directoryOf(final_path);
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0)
    return fail(ioCode(errno), fmt::format("{}: output directory {} is not accessible: {}",
                                           final_path, dir, errnoText(errno)));
  if (!S_ISDIR(st.st_mode))
    return fail(ErrorCode::kIo, fmt::format("{}: {} is not a directory", final_path, dir));
  int fd = ::open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0644);
  if (fd >= 0) return TempFile(fd, final_path, "");
  if (errno != EOPNOTSUPP && errno != EISDIR && errno != EINVAL && errno != ENOENT)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot create a file in {}: {}", final_path, dir,
                                            errnoText(errno)));
  // File systems without O_TMPFILE: a named temporary, removed by the destructor.
  static std::atomic<uint32_t> counter{0};
  std::string temp = fmt::format("{}.tmp-{}-{}", final_path, ::getpid(), counter++);
  fd = ::open(temp.c_str(), O_CREAT | O_EXCL | O_RDWR | O_CLOEXEC, 0644);
  if (fd < 0)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot create temporary {}: {}", final_path, temp,
                                            errnoText(errno)));
  return TempFile(fd, final_path, temp);
}

TempFile::TempFile(TempFile&& other) noexcept
    : fd_(other.fd_),
      final_path_(std::move(other.final_path_)),
      temp_path_(std::move(other.temp_path_)),
      committed_(other.committed_) {
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

Result<void> TempFile::commit() {
  if (::fsync(fd_) != 0)
    return fail(ErrorCode::kIo, fmt::format("{}: fsync failed: {}", final_path_, errnoText(errno)));
  std::string named = temp_path_;
  if (named.empty()) {
    // Give the anonymous file a unique name beside the target, then rename it over the target:
    // linkat cannot replace an existing file, rename can, atomically.
    static std::atomic<uint32_t> counter{0};
    named = fmt::format("{}.tmp-{}-{}", final_path_, ::getpid(), counter++);
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
