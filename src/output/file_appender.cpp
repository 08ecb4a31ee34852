#include "output/file_appender.h"

namespace tessera::detail {

FileAppender::FileAppender(const TempFile& out, uint64_t start)
    : out_(out), end_(start), flushed_(start) {}

Result<uint64_t> FileAppender::append(std::span<const uint8_t> bytes) {
  const uint64_t offset = end_;
  if (buffer_.size() + bytes.size() > kBufferBytes) TESSERA_TRY(flush());
  if (bytes.size() > kBufferBytes) {
    TESSERA_TRY(out_.pwrite(flushed_, bytes));
    flushed_ += bytes.size();
  } else {
    // Reserved on first use, not at construction: an appender that only skips costs nothing.
    if (buffer_.capacity() < kBufferBytes) buffer_.reserve(kBufferBytes);
    buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  }
  end_ += bytes.size();
  return offset;
}

Result<uint64_t> FileAppender::skip(uint64_t bytes) {
  TESSERA_TRY(flush());
  const uint64_t offset = end_;
  end_ += bytes;
  flushed_ = end_;
  return offset;
}

Result<void> FileAppender::flush() {
  if (buffer_.empty()) return {};
  TESSERA_TRY(out_.pwrite(flushed_, buffer_));
  flushed_ += buffer_.size();
  buffer_.clear();
  return {};
}

}  // namespace tessera::detail
