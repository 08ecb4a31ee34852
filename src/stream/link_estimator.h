#pragma once
// What the loader measures of the link between the reader and its bytes, whatever the source
// (file, HTTP, simulated): throughput, latency and queue wait, fed with every read it makes.
// Adaptive scheduling (Marvie & Bouatouch, "Remote Rendering of Massively Textured 3D Scenes
// Through Progressive Texture Maps", part III) sizes its requests by it; FrameReport carries
// its figures (docs/runtime.md, "Measuring the link").

#include <chrono>
#include <cstdint>
#include <deque>
#include <mutex>
#include <utility>

namespace tessera::detail {

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

}  // namespace tessera::detail
