#pragma once
// Appending many small blocks to a file being written, through one large buffer, so thousands
// of tile payloads or scene nodes cost a few large writes.

#include <cstdint>
#include <cstdlib>
#include <functional>
#include <memory>
#include <span>

#include <tessera/result.h>

#include "output/output_file.h"

namespace tessera::detail {

/// Appends at the end of a TempFile from `start`. Owned by one thread. Bytes are in the file
/// only after flush(); the TempFile must outlive the appender.
class FileAppender {
 public:
  /// Bytes held before a write; a larger block is written directly.
  static constexpr size_t kBufferBytes = 1u << 20;

  FileAppender(const TempFile& out, uint64_t start);

  /// Appends `bytes`; returns the offset they start at.
  [[nodiscard]] Result<uint64_t> append(std::span<const uint8_t> bytes);
  /// Appends `size` bytes that `fill` writes straight into the buffer (a copy saved when the
  /// bytes come from a read); returns the offset they start at. Nothing is appended when
  /// `fill` fails. A block larger than the buffer is filled in its own allocation.
  [[nodiscard]] Result<uint64_t> appendFilled(
      size_t size, const std::function<Result<void>(std::span<uint8_t>)>& fill);
  /// Leaves a hole of `bytes` (filled later with TempFile::pwrite, e.g. a head known only
  /// after its body); returns the offset it starts at.
  [[nodiscard]] Result<uint64_t> skip(uint64_t bytes);
  /// Writes what is buffered.
  [[nodiscard]] Result<void> flush();
  /// The offset the next append starts at.
  uint64_t end() const { return end_; }

 private:
  const TempFile& out_;
  uint64_t end_;
  uint64_t flushed_;
  // Page-aligned and never zero-filled: every byte is written before it is flushed.
  std::unique_ptr<uint8_t, decltype(&std::free)> buffer_{nullptr, &std::free};
  size_t buffered_ = 0;
};

}  // namespace tessera::detail
