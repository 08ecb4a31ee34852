#include "output/file_appender.h"

#include <condition_variable>
#include <cstring>
#include <mutex>
#include <new>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

namespace tessera::detail {

namespace {

/// Page alignment lets the kernel copy whole pages out of the buffer.
constexpr size_t kBufferAlignment = 4096;

}  // namespace

/// A block for the file: the appender's buffer or bytes it does not own.
struct FileAppender::Job {
  Buffer buffer{nullptr, &std::free};  ///< when writing the appender's buffer
  OwnedBytes owned;                    ///< otherwise
  size_t bytes = 0;
  uint64_t offset_bytes = 0;

  Job() = default;
  Job(Job&&) = default;
  Job& operator=(Job&&) = default;
  ~Job() { release(); }

  const uint8_t* data() const { return buffer ? buffer.get() : owned.bytes.data(); }
  /// Frees owned bytes (once); a buffer is kept for reuse.
  void release() {
    if (owned.release) std::exchange(owned.release, nullptr)();
  }
};

/// The second thread of AppendWrites::kBackground: writes one job at a time, then asks the
/// kernel to start writing it to the disk, while the appender fills the next.
class FileAppender::BackgroundWriter {
 public:
  /// Null when the system refuses the thread.
  static std::unique_ptr<BackgroundWriter> start(const TempFile& out) {
    auto writer = std::unique_ptr<BackgroundWriter>(new BackgroundWriter(out));
    try {
      writer->thread_ = std::thread([w = writer.get()] { w->run(); });
    } catch (const std::system_error&) {
      return nullptr;
    }
    return writer;
  }

  /// A write in flight completes first.
  ~BackgroundWriter() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    thread_.join();
  }

  /// Writes `job`; the writer holds it until wait() gives its buffer back. Only while idle
  /// (after wait()).
  void submit(Job job) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      job_ = std::move(job);
      busy_ = true;
    }
    changed_.notify_all();
  }

  /// Waits until the writer is idle; returns the first failed write not yet returned and
  /// moves the last job's buffer, if any, to `returned`.
  Result<void> wait(Buffer& returned) {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [&] { return !busy_; });
    if (job_.buffer) returned = std::move(job_.buffer);
    return std::exchange(result_, Result<void>());
  }

 private:
  explicit BackgroundWriter(const TempFile& out) : out_(out) {}

  void run() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      changed_.wait(lock, [&] { return busy_ || stop_; });
      if (!busy_) return;  // stopping, nothing left to write
      lock.unlock();
      // The appender leaves job_ alone while busy_.
      Result<void> written = out_.pwrite(job_.offset_bytes, {job_.data(), job_.bytes});
      if (written) out_.startWriteback(job_.offset_bytes, job_.bytes);
      job_.release();
      lock.lock();
      if (!written && result_) result_ = std::move(written);
      busy_ = false;
      changed_.notify_all();
    }
  }

  const TempFile& out_;
  std::thread thread_;
  std::mutex mutex_;  // guards every field below
  std::condition_variable changed_;
  Job job_;
  bool busy_ = false;  ///< job_ is submitted and not yet written
  bool stop_ = false;
  Result<void> result_;  ///< the first failed write not yet returned by wait()
};

FileAppender::FileAppender(const TempFile& out, uint64_t start, AppendWrites writes)
    : out_(out), end_(start), flushed_(start), writes_(writes) {}

FileAppender::FileAppender(FileAppender&&) noexcept = default;

FileAppender::~FileAppender() = default;

Result<uint64_t> FileAppender::append(std::span<const uint8_t> bytes) {
  return appendFilled(bytes.size(), [&](std::span<uint8_t> place) -> Result<void> {
    if (!bytes.empty()) std::memcpy(place.data(), bytes.data(), bytes.size());
    return {};
  });
}

Result<uint64_t> FileAppender::appendFilled(
    size_t size, const std::function<Result<void>(std::span<uint8_t>)>& fill) {
  const uint64_t offset = end_;
  if (buffered_ + size > kBufferBytes) TESSERA_TRY(handOff());
  if (size > kBufferBytes) {
    // Beside a background write in flight, at offsets after it: the two do not overlap.
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

Result<uint64_t> FileAppender::appendOwned(OwnedBytes block) {
  const size_t bytes = block.bytes.size();
  Job job;  // releases the block on a failure before the write takes it
  job.owned = std::move(block);
  job.bytes = bytes;
  TESSERA_TRY(handOff());
  TESSERA_TRY(write(std::move(job)));
  const uint64_t offset = end_;
  end_ += bytes;
  return offset;
}

Result<void> FileAppender::handOff() {
  if (buffered_ == 0) return {};
  Job job;
  job.buffer = std::move(buffer_);
  job.bytes = buffered_;
  buffered_ = 0;
  TESSERA_TRY(write(std::move(job)));
  return {};
}

Result<void> FileAppender::write(Job&& job) {
  job.offset_bytes = flushed_;
  if (writes_ == AppendWrites::kBackground && !writer_) {
    writer_ = BackgroundWriter::start(out_);
    if (!writer_) writes_ = AppendWrites::kInline;
  }
  const size_t bytes = job.bytes;
  if (!writer_) {
    TESSERA_TRY(out_.pwrite(job.offset_bytes, {job.data(), bytes}));
    out_.startWriteback(job.offset_bytes, bytes);
    job.release();
    if (job.buffer && !buffer_) buffer_ = std::move(job.buffer);
  } else {
    Buffer spare{nullptr, &std::free};
    TESSERA_TRY(writer_->wait(spare));
    writer_->submit(std::move(job));
    if (!buffer_) buffer_ = std::move(spare);  // null on the first hand-off: allocated on use
  }
  flushed_ += bytes;
  return {};
}

Result<void> FileAppender::waitForWriter() {
  if (!writer_) return {};
  Buffer spare{nullptr, &std::free};
  TESSERA_TRY(writer_->wait(spare));
  if (!buffer_) buffer_ = std::move(spare);
  return {};
}

Result<void> FileAppender::flush() {
  TESSERA_TRY(handOff());
  return waitForWriter();
}

}  // namespace tessera::detail
