#include <tessera/byte_source.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fmt/format.h>

namespace tessera {

namespace {

// pread rather than mmap: reads from many threads need no shared offset, and a failing disk
// or a file truncated under us surfaces as an error value instead of SIGBUS.
class FileSource final : public ByteSource {
 public:
  FileSource(int fd, uint64_t size_bytes, std::string path)
      : fd_(fd), size_bytes_(size_bytes), path_(std::move(path)) {}
  ~FileSource() override { ::close(fd_); }

  uint64_t sizeBytes() const override { return size_bytes_; }
  const std::string& name() const override { return path_; }

  Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override {
    if (offset_bytes > size_bytes_ || out.size() > size_bytes_ - offset_bytes)
      return fail(ErrorCode::kIo, fmt::format("{}: read [{}, +{}) past the end ({} bytes)", path_,
                                              offset_bytes, out.size(), size_bytes_));
    size_t done = 0;
    while (done < out.size()) {
      ssize_t n = ::pread(fd_, out.data() + done, out.size() - done, off_t(offset_bytes + done));
      if (n < 0) {
        if (errno == EINTR) continue;
        return fail(ErrorCode::kIo, fmt::format("{}: read at offset {} failed: {}", path_,
                                                offset_bytes + done, std::strerror(errno)));
      }
      if (n == 0)
        return fail(ErrorCode::kIo, fmt::format("{}: file ended at offset {} (shrunk after open?)",
                                                path_, offset_bytes + done));
      done += size_t(n);
    }
    return {};
  }

  // posix_fadvise(WILLNEED) queues the reads in the kernel and returns (it does not wait
  // for them), so many ranges are in flight at once; pages already cached cost a lookup.
  uint64_t prefetch(std::span<const ByteRange> ranges) const override {
    uint64_t asked = 0;
    for (const ByteRange& range : ranges) {
      if (range.offset_bytes >= size_bytes_ || range.length_bytes == 0) continue;
      const uint64_t length = std::min(range.length_bytes, size_bytes_ - range.offset_bytes);
      if (::posix_fadvise(fd_, off_t(range.offset_bytes), off_t(length), POSIX_FADV_WILLNEED) == 0)
        asked += length;
    }
    return asked;
  }

 private:
  int fd_;
  uint64_t size_bytes_;
  std::string path_;
};

}  // namespace

Result<std::shared_ptr<ByteSource>> openFileSource(const std::string& path) {
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer; it is refused
  // below as not a regular file (for which the flag changes nothing).
  int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    int error = errno;
    return fail(error == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                fmt::format("{}: cannot open: {}", path, std::strerror(error)));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return fail(ErrorCode::kIo, fmt::format("{}: not a regular file", path));
  }
  return std::shared_ptr<ByteSource>(std::make_shared<FileSource>(fd, uint64_t(st.st_size), path));
}

}  // namespace tessera
