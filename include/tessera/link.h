#pragma once
/// \file
/// The link between a reader and its bytes: an estimator of throughput and latency fed with
/// every read the loader makes (any source: file, HTTP, simulated), and a simulated network
/// link that wraps any byte source, for tests, benchmarks and `tessera fly --link`.
/// Marvie & Bouatouch, "Remote Rendering of Massively Textured 3D Scenes Through Progressive
/// Texture Maps", part III: the client adapts what it requests to the measured bandwidth.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <tessera/byte_source.h>
#include <tessera/result.h>

namespace tessera {

/// What the estimator believes about the link now.
struct LinkEstimate {
  /// Bytes delivered per second of wall time while at least one read was in flight: what the
  /// reader achieves with the parallelism it uses, latency included. 0 until a read finished.
  double bytes_per_s = 0;
  /// Time from a request to its first byte, bounded from above by the shortest recent read
  /// (a min-filter: the smallest reads are mostly round trip). The first byte's time is not
  /// visible through ByteSource::read.
  double latency_s = 0;
  /// Time a tile waited from being requested to its read starting (an average over recent
  /// tiles): how far behind the loader's queue is.
  double queue_wait_s = 0;
  uint64_t reads = 0;  ///< reads measured so far (successful ones)
  uint64_t bytes = 0;  ///< bytes those reads delivered
  /// Bytes that can arrive within `seconds` from now at this estimate: bytes_per_s x
  /// (seconds - latency_s), at least 0.
  double bytesWithin(double seconds) const;
};

/// Throughput and latency from a stream of reads. Thread-safe: loader threads report their
/// reads as they start and finish. Times are passed in, so tests feed synthetic samples.
class LinkEstimator {
 public:
  using Clock = std::chrono::steady_clock;
  struct Options {
    /// Busy seconds over which throughput is averaged (exponential weights): older reads
    /// count e^-1 less per window. Idle time does not age the estimate.
    double window_s = 2.0;
    /// Reads over which the latency minimum is taken (a sliding window, so the estimate
    /// follows a link whose latency grows).
    uint32_t latency_reads = 32;
    /// Weight of one tile's queue wait in the queue-wait average.
    double queue_wait_weight = 0.1;
  };
  LinkEstimator() : LinkEstimator(Options{}) {}
  explicit LinkEstimator(const Options& options);

  /// A read began at `at`.
  void readStarted(Clock::time_point at);
  /// The read that began at `started` ended at `finished`. `bytes` it delivered (0 for a read
  /// that failed or was cancelled: its busy time then counts towards the next sample).
  void readFinished(Clock::time_point started, Clock::time_point finished, uint64_t bytes);
  /// A tile requested `waited` before its read started.
  void queueWait(Clock::duration waited);

  LinkEstimate estimate() const;

 private:
  void accountBusyLocked(Clock::time_point at);

  Options options_;
  mutable std::mutex mutex_;  // guards everything below
  uint32_t in_flight_ = 0;
  Clock::time_point last_event_{};
  double pending_busy_s_ = 0;  ///< busy time since the last sample
  double weighted_bytes_ = 0;
  double weighted_busy_s_ = 0;
  std::deque<std::pair<double, double>> recent_;  ///< (duration s, bytes) of recent reads
  double queue_wait_s_ = -1;
  uint64_t reads_ = 0;
  uint64_t bytes_ = 0;
};

/// A simulated network link (tests, benchmarks, `tessera fly --link`).
struct LinkModel {
  double bits_per_s = 20e6;  ///< shared by every read in flight
  double rtt_s = 0.04;       ///< per read: the request goes out and the first byte comes back
};

/// Parses "RATE:RTT", e.g. "20mbit:40ms", "2mbit:150ms", "500kbit:0.3s", "1gbit:2ms":
/// RATE in bit, kbit, mbit or gbit (per second; k = 1000), RTT in us, ms or s. Fails naming
/// the text and what is wrong.
[[nodiscard]] Result<LinkModel> parseLinkModel(const std::string& text);

/// What a throttled source transferred.
struct LinkStatsTotal {
  uint64_t reads = 0;            ///< reads started
  uint64_t bytes = 0;            ///< bytes that crossed the simulated link
  uint64_t reads_cancelled = 0;  ///< reads abandoned through readCancellable's flag
};

/// A byte source behind a simulated link: each read waits its round trip, then its bytes
/// cross a link of `bits_per_s` shared by all reads in flight (fair, in slices of 5 ms of
/// link time), then comes from `inner`. `readCancellable` stops at the next
/// slice once its flag is set, counting only the bytes that crossed. Prefetch hints are not
/// passed on: the link is the bottleneck being simulated. The waits are the simulation, not
/// synchronisation.
class ThrottledSource final : public ByteSource {
 public:
  ThrottledSource(std::shared_ptr<ByteSource> inner, const LinkModel& link);
  uint64_t sizeBytes() const override;
  const std::string& name() const override;
  [[nodiscard]] Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override;
  [[nodiscard]] Result<void> readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                                             const std::atomic<bool>& cancel) const override;
  const LinkModel& link() const { return link_; }
  LinkStatsTotal totals() const;
  /// The same figures as a network source gives them (requests, bytes received, cancelled,
  /// in flight, the last 64 reads with their round trip as the first byte's time).
  std::optional<LinkStats> linkStats() const override;

 private:
  using Clock = std::chrono::steady_clock;
  /// Waits until `deadline`; false as soon as `cancel` is seen set. Nothing signals a bare
  /// atomic flag, so the wait looks at it every kCancelCheck, as a network client looks
  /// between two receives.
  bool waitUntil(Clock::time_point deadline, const std::atomic<bool>* cancel) const;
  Result<void> transfer(uint64_t offset_bytes, std::span<uint8_t> out,
                        const std::atomic<bool>* cancel) const;

  std::shared_ptr<ByteSource> inner_;
  LinkModel link_;
  std::string name_;
  mutable std::mutex mutex_;                  // guards everything below
  mutable std::condition_variable wait_;      ///< timed waits only
  mutable Clock::time_point link_free_at_{};  ///< the link carries reserved slices until then
  mutable LinkStatsTotal totals_;
  mutable uint32_t in_flight_ = 0;
  mutable std::deque<LinkSample> recent_;
};

/// `inner` behind a simulated link.
std::shared_ptr<ThrottledSource> makeThrottledSource(std::shared_ptr<ByteSource> inner,
                                                     const LinkModel& link);

}  // namespace tessera
