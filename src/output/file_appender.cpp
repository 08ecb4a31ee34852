#include "output/file_appender.h"

#include <cstring>
#include <new>
#include <vector>

namespace tessera::detail {

namespace {

/// Page alignment lets the kernel copy whole pages out of the buffer.
constexpr size_t kBufferAlignment = 4096;

}  // namespace

FileAppender::FileAppender(const TempFile& out, uint64_t start)
    : out_(out), end_(start), flushed_(start) {}

Result<uint64_t> FileAppender::append(std::span<const uint8_t> bytes) {
  return appendFilled(bytes.size(), [&](std::span<uint8_t> place) -> Result<void> {
    if (!bytes.empty()) std::memcpy(place.data(), bytes.data(), bytes.size());
    return {};
  });
}

Result<uint64_t> FileAppender::appendFilled(
    size_t size, const std::function<Result<void>(std::span<uint8_t>)>& fill) {
  const uint64_t offset = end_;
  if (buffered_ + size > kBufferBytes) TESSERA_TRY(flush());
  if (size > kBufferBytes) {
    std::vector<uint8_t> block(size);
    TESSERA_TRY(fill(block));
    TESSERA_TRY(out_.pwrite(flushed_, block));
    flushed_ += size;
  } else {
    // Allocated on first use, not at construction: an appender that only skips costs nothing.
    if (!buffer_) {
      buffer_.reset(static_cast<uint8_t*>(std::aligned_alloc(kBufferAlignment, kBufferBytes)));
      if (!buffer_) throw std::bad_alloc();
    }
    TESSERA_TRY(fill({buffer_.get() + buffered_, size}));
    buffered_ += size;
  }
  end_ += size;
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
  if (buffered_ == 0) return {};
  TESSERA_TRY(out_.pwrite(flushed_, {buffer_.get(), buffered_}));
  out_.startWriteback(flushed_, buffered_);
  flushed_ += buffered_;
  buffered_ = 0;
  return {};
}

}  // namespace tessera::detail
