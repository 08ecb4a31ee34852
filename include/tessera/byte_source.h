#pragma once
/// \file
/// Byte sources: where archive bytes come from (a local file, memory; HTTP ranges in
/// tessera/http_source.h; a path or URL in tessera/open.h). The archive reader and the loader
/// pool see only this interface.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <tessera/result.h>

namespace tessera {

/// One range of a batched read. `out` must hold `length_bytes` bytes.
struct ByteRange {
  uint64_t offset_bytes = 0;
  uint64_t length_bytes = 0;
  uint8_t* out = nullptr;
};

/// One finished request of a remote source: what a bandwidth or latency estimate is made of.
struct LinkSample {
  std::chrono::steady_clock::time_point finished;  ///< when its last byte arrived
  uint64_t bytes = 0;                              ///< body bytes received
  double seconds = 0;                              ///< from the request's start to its last byte
  double first_byte_seconds = 0;  ///< from the request's start to its first byte (latency)
};

/// Counters of a source whose reads cross a network link (ByteSource::linkStats). Totals
/// since the source was opened; every request counts, prefetches and retries included.
struct LinkStats {
  uint64_t requests = 0;            ///< requests sent (each retry is one more)
  uint64_t bytes_received = 0;      ///< body bytes received, including aborted transfers
  uint64_t retries = 0;             ///< requests that were a retry of a failed one
  uint64_t errors = 0;              ///< reads (and prefetches) that failed after their retries
  uint64_t cancelled = 0;           ///< reads abandoned through readCancellable
  uint64_t prefetched_bytes = 0;    ///< bytes fetched ahead on a prefetch hint
  uint64_t prefetch_hit_bytes = 0;  ///< bytes reads then took from fetched-ahead data
  uint32_t in_flight = 0;           ///< requests on the wire now
  uint32_t max_in_flight = 0;       ///< the most requests on the wire at once so far
  /// Connections opened (TCP, plus TLS for https://), and of those the ones that spoke
  /// HTTP/1.x and HTTP/2 (negotiated by ALPN, or h2c prior knowledge). A connection that
  /// failed before a response counts in `connections` only.
  uint64_t connections = 0;
  uint64_t http1_connections = 0;
  uint64_t http2_connections = 0;
  /// The last (at most 64) successful requests, oldest first: bytes over seconds is the
  /// throughput one request saw, first_byte_seconds the round trip plus server time.
  std::vector<LinkSample> recent;
};

/// Random-access, read-only bytes. Thread-safe: `read` may be called from many threads at once.
class ByteSource {
 public:
  virtual ~ByteSource() = default;

  /// Total size in bytes, known at open.
  virtual uint64_t sizeBytes() const = 0;

  /// A name for messages: a path or URL.
  virtual const std::string& name() const = 0;

  /// Reads exactly `out.size()` bytes at `offset_bytes`. A range past the end, a short read or
  /// an I/O error is an error naming the source, the offset and the cause; `out` is then
  /// unspecified.
  [[nodiscard]] virtual Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const = 0;

  /// Reads several ranges (any order, may overlap). The default sorts them and reads ranges
  /// closer than 64 KiB as one (at most 16 MiB per read), which suits disks and HTTP alike;
  /// sources may override it (the HTTP source sends those reads at once, in parallel). Fails
  /// as a whole if any read fails.
  [[nodiscard]] virtual Result<void> readMany(std::span<const ByteRange> ranges) const;

  /// Reads several ranges, each on its own: element i of the result is range i's outcome, so
  /// one bad range (an I/O error, a server's mislabelled part) fails only itself, and the bytes
  /// of a range that failed are unspecified. Ranges are in any order and should not overlap.
  /// Once `cancel` becomes true, ranges not yet read fail with ErrorCode::kCancelled. The
  /// default reads them one after another through readCancellable (local reads are short);
  /// the HTTP source sends them together, as few multi-range requests as the server allows.
  [[nodiscard]] virtual std::vector<Result<void>> readEach(std::span<const ByteRange> ranges,
                                                           const std::atomic<bool>& cancel) const;

  /// True when readEach of several ranges costs fewer round trips than reading them one by one
  /// (a network source): the loader then hands it a batch's reads at once, and Archive::open
  /// reads the directory of the coarse levels ahead in one readEach. Default false.
  virtual bool readsRangesTogether() const { return false; }

  /// A hint that these ranges will be read soon (`out` is ignored). A source that can fetch
  /// ahead starts on them and returns without waiting for the data, so the reads that follow
  /// find it arriving or arrived: the loader hints the tiles queued behind the ones it reads,
  /// which keeps a disk busy with many requests instead of one at a time. Never fails; the
  /// default does nothing. Returns the bytes it asked for (0 when it does nothing).
  virtual uint64_t prefetch(std::span<const ByteRange> ranges) const;

  /// `read`, for a reader that may stop wanting the bytes while they are on their way: once
  /// `cancel` becomes true a source whose reads take a network round trip abandons the read
  /// and fails it with ErrorCode::kCancelled, so a request no view wants any more stops using
  /// the link (Marvie & Bouatouch, part III: requests that left the view are cancelled). The
  /// default checks `cancel` once, before reading; a local read is too short to interrupt.
  [[nodiscard]] virtual Result<void> readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                                                     const std::atomic<bool>& cancel) const;

  /// For sources that read over a network link: request, byte, retry and error counts and
  /// the latest per-request throughput and latency samples (the HTTP source; a scheduler
  /// adapts to the link by them). Local sources return nullopt, the default. Thread-safe;
  /// a snapshot, cheap enough to call once per frame.
  virtual std::optional<LinkStats> linkStats() const { return std::nullopt; }
};

/// Opens a local file for positional reads (pread: thread-safe without a shared file offset,
/// and an I/O error is an error value, not a SIGBUS as with mmap). Fails naming the path.
[[nodiscard]] Result<std::shared_ptr<ByteSource>> openFileSource(const std::string& path);

/// Wraps bytes held in memory; `name` is used in messages.
std::shared_ptr<ByteSource> makeMemorySource(std::vector<uint8_t> bytes, std::string name);

}  // namespace tessera
