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

/// How a full buffer reaches the file.
enum class AppendWrites {
  kInline,      ///< written by the appending thread, one buffer
  kBackground,  ///< written by a second thread while the next is filled (two buffers)
};

/// Bytes appended as they lie, without a copy into the appender's buffer (a buffer the caller
/// filled and reuses), and what gives them back once written.
struct OwnedBytes {
  std::span<const uint8_t> bytes;
  std::function<void()> release;  ///< called once, after the write (or when dropped); may be empty
};

/// Appends at the end of a TempFile from `start`. Owned by one thread (with kBackground it
/// starts a writer thread of its own, which flush() waits for and the destructor joins). Bytes
/// are in the file only after flush(); the TempFile must outlive the appender.
class FileAppender {
 public:
  /// Bytes held before a write; a larger block is written directly.
  static constexpr size_t kBufferBytes = 1u << 20;

  /// kBackground suits a writer whose filling costs as much as the write (payloads read from
  /// other files): the two overlap. Where the system refuses the thread it writes inline.
  FileAppender(const TempFile& out, uint64_t start, AppendWrites writes = AppendWrites::kInline);
  FileAppender(FileAppender&&) noexcept;
  FileAppender& operator=(FileAppender&&) = delete;
  /// Waits for a background write in flight; what is still buffered is dropped.
  ~FileAppender();

  /// Appends `bytes`; returns the offset they start at.
  [[nodiscard]] Result<uint64_t> append(std::span<const uint8_t> bytes);
  /// Appends `size` bytes that `fill` writes straight into the buffer (a copy saved when the
  /// bytes come from a read); returns the offset they start at. Nothing is appended when
  /// `fill` fails. A block larger than the buffer is filled in its own allocation.
  [[nodiscard]] Result<uint64_t> appendFilled(
      size_t size, const std::function<Result<void>(std::span<uint8_t>)>& fill);
  /// Appends `block` straight from where it lies (after what is buffered); returns the offset
  /// it starts at. With kBackground it is written, and released, on the writer thread while the
  /// caller goes on; on a failure it is released here.
  [[nodiscard]] Result<uint64_t> appendOwned(OwnedBytes block);
  /// Leaves a hole of `bytes` (filled later with TempFile::pwrite, e.g. a head known only
  /// after its body); returns the offset it starts at.
  [[nodiscard]] Result<uint64_t> skip(uint64_t bytes);
  /// Writes what is buffered and waits for any background write: the bytes are then in the
  /// file. A background write's failure is returned by the next call that waits for it.
  [[nodiscard]] Result<void> flush();
  /// The offset the next append starts at.
  uint64_t end() const { return end_; }

 private:
  class BackgroundWriter;
  struct Job;
  using Buffer = std::unique_ptr<uint8_t, decltype(&std::free)>;
  /// Starts writing what is buffered (in the background where there is a writer).
  Result<void> handOff();
  /// Writes `job` at flushed_ and advances flushed_: here, or handed to the writer (then
  /// moved from) once it has finished the previous one.
  Result<void> write(Job&& job);
  /// Waits for the background write in flight, if any, and returns its outcome.
  Result<void> waitForWriter();

  const TempFile& out_;
  uint64_t end_;
  uint64_t flushed_;
  // Page-aligned and never zero-filled: every byte is written before it is flushed.
  Buffer buffer_{nullptr, &std::free};
  size_t buffered_ = 0;
  AppendWrites writes_;
  std::unique_ptr<BackgroundWriter> writer_;  ///< started on the first hand-off
};

}  // namespace tessera::detail
