#include "archive_tail.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

#include "format/checksum.h"
#include "format/metadata.h"

namespace tessera::detail {

namespace {

Result<void> preadAll(int fd, uint64_t offset, std::span<uint8_t> out, const std::string& what) {
  size_t done = 0;
  while (done < out.size()) {
    ssize_t n = ::pread(fd, out.data() + done, out.size() - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      return fail(ErrorCode::kIo, fmt::format("{}: cannot read {} bytes at {}: {}", what,
                                              out.size(), offset, n < 0 ? strerror(errno) : "end"));
    done += size_t(n);
  }
  return {};
}

Result<void> pwriteAll(int fd, uint64_t offset, std::span<const uint8_t> bytes,
                       const std::string& what) {
  size_t done = 0;
  while (done < bytes.size()) {
    ssize_t n = ::pwrite(fd, bytes.data() + done, bytes.size() - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      return fail(ErrorCode::kIo, fmt::format("{}: cannot write {} bytes at {}: {}", what,
                                              bytes.size(), offset, strerror(errno)));
    done += size_t(n);
  }
  return {};
}

}  // namespace

Result<ArchiveTail> ArchiveTail::open(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);  // a FIFO must not block
  if (fd < 0)
    return fail(ErrorCode::kIo,
                fmt::format("{}: cannot open for update: {}", path, strerror(errno)));
  ArchiveTail tail(fd, path);
  struct stat status {};
  if (::fstat(fd, &status) != 0 || !S_ISREG(status.st_mode))
    return fail(ErrorCode::kInvalidArgument, path + ": not a regular file");
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0)
    return fail(ErrorCode::kIo, path + ": another update of this archive is running (locked)");
  TESSERA_TRY(tail.load());
  return tail;
}

ArchiveTail::ArchiveTail(ArchiveTail&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      path_(std::move(other.path_)),
      header_(other.header_),
      records_(std::move(other.records_)),
      metadata_(std::move(other.metadata_)),
      version_(other.version_),
      dead_bytes_(other.dead_bytes_),
      end_bytes_(other.end_bytes_) {}

ArchiveTail::~ArchiveTail() {
  if (fd_ >= 0) ::close(fd_);  // also releases the lock
}

Result<void> ArchiveTail::sync() {
  if (::fdatasync(fd_) != 0)
    return fail(ErrorCode::kIo, fmt::format("{}: fdatasync failed: {}", path_, strerror(errno)));
  return {};
}

Result<void> ArchiveTail::load() {
  struct stat status {};
  if (::fstat(fd_, &status) != 0)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot stat: {}", path_, strerror(errno)));
  const uint64_t size = uint64_t(status.st_size);
  if (size < kHeaderBytes) return fail(ErrorCode::kCorrupt, path_ + ": not a Tessera archive");
  std::vector<uint8_t> header_bytes(kHeaderBytes);
  TESSERA_TRY(preadAll(fd_, 0, header_bytes, path_));
  Result<FileHeader> header = decodeHeader(header_bytes, path_);
  if (!header && header.error().code == ErrorCode::kCorrupt && size >= 2 * kHeaderBytes) {
    // A torn header write: the copy at the end was synced before it began (the commit).
    std::vector<uint8_t> copy_bytes(kHeaderBytes);
    TESSERA_TRY(preadAll(fd_, size - kHeaderBytes, copy_bytes, path_));
    Result<FileHeader> copy = decodeHeader(copy_bytes, path_ + ": header copy");
    if (copy && copy->file_bytes == size) {
      TESSERA_TRY(pwriteAll(fd_, 0, copy_bytes, path_ + ": header repair"));
      TESSERA_TRY(sync());
      header = copy;
    }
  }
  if (!header) return Unexpected(header.error());
  header_ = *header;
  if (header_.version_minor != 0) {
    const char* why = header_.version_minor == 2 ? "an image with u16 or f32 samples"
                                                 : "scene or procedural sections";
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: format {}.{} archive ({}): only 1.0 archives of 8-bit images "
                            "can be updated",
                            path_, header_.version_major, header_.version_minor, why));
  }
  if (header_.file_bytes > size)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: header records {} bytes, the file has {}",
                                                 path_, header_.file_bytes, size));
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> root, readBlock(header_.root, "root directory"));
  TESSERA_ASSIGN_OR_RETURN(records_, decodeRootDirectory(root, header_, path_));
  metadata_ = nlohmann::json::object();
  if (header_.metadata.length_bytes > 0) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> json, readBlock(header_.metadata, "metadata"));
    metadata_ = nlohmann::json::parse(json.begin(), json.end(), nullptr, false);
    if (!metadata_.is_object())
      return fail(ErrorCode::kCorrupt, path_ + ": metadata is not a JSON object");
  }
  // The next commit counts on from these: a damaged record is refused, not overwritten.
  TESSERA_ASSIGN_OR_RETURN(const UpdateRecord update, parseUpdateRecord(metadata_, path_));
  version_ = update.version;
  dead_bytes_ = update.dead_bytes;
  // Nothing references an uncommitted tail; cutting it keeps the file free of garbage.
  if (size > header_.file_bytes && ::ftruncate(fd_, off_t(header_.file_bytes)) != 0)
    return fail(ErrorCode::kIo,
                fmt::format("{}: cannot cut the uncommitted tail: {}", path_, strerror(errno)));
  end_bytes_ = header_.file_bytes;
  return {};
}

Result<std::vector<uint8_t>> ArchiveTail::readBlock(const BlockRef& block,
                                                    const std::string& what) const {
  std::vector<uint8_t> bytes(block.length_bytes);
  TESSERA_TRY(preadAll(fd_, block.offset_bytes, bytes, path_ + ": " + what));
  if (checksum64(bytes) != block.checksum)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} at {} fails its checksum", path_, what, block.offset_bytes));
  return bytes;
}

Result<BlockRef> ArchiveTail::append(std::span<const uint8_t> bytes) {
  BlockRef block{end_bytes_, bytes.size(), checksum64(bytes)};
  TESSERA_TRY(pwriteAll(fd_, end_bytes_, bytes, path_));
  end_bytes_ += bytes.size();
  return block;
}

Result<UpdateReport> ArchiveTail::commit() {
  const uint64_t committed_bytes = header_.file_bytes;
  FileHeader next = header_;
  next.image_count = uint32_t(records_.size());
  TESSERA_ASSIGN_OR_RETURN(next.root, append(encodeRootDirectory(records_)));
  dead_bytes_ += header_.root.length_bytes + header_.metadata.length_bytes;
  if (version_ > 1) dead_bytes_ += kHeaderBytes;  // the previous version's header copy
  metadata_["update"] = {{"version", version_ + 1}, {"dead_bytes", dead_bytes_}};
  const std::string json = metadata_.dump();
  TESSERA_ASSIGN_OR_RETURN(next.metadata,
                           append({reinterpret_cast<const uint8_t*>(json.data()), json.size()}));
  next.file_bytes = end_bytes_ + kHeaderBytes;
  const std::vector<uint8_t> header_bytes = encodeHeader(next);
  TESSERA_TRY(append(header_bytes));
  // Everything the new header references is durable before the header changes.
  TESSERA_TRY(sync());
  TESSERA_TRY(pwriteAll(fd_, 0, header_bytes, path_ + ": header"));
  TESSERA_TRY(sync());
  header_ = next;
  ++version_;
  UpdateReport report;
  report.version = version_;
  report.bytes_written = end_bytes_ - committed_bytes + kHeaderBytes;
  report.dead_bytes = dead_bytes_;
  report.file_bytes = end_bytes_;
  return report;
}

}  // namespace tessera::detail
