#pragma once
// Server metrics in the Prometheus text exposition format (version 0.0.4): requests by
// endpoint and status, body bytes, a latency histogram, connection and error counters.

#include <array>
#include <atomic>
#include <cstdint>
#include <string>

#include "transcode_cache.h"

namespace tessera::detail {

/// The endpoint a request was routed to, the `endpoint` label.
enum class Endpoint : uint8_t {
  kViewer,
  kHealth,
  kMetrics,
  kArchives,
  kInfo,
  kTile,
  kArchiveFile,
  kDzi,
  kDziTile,
  kXyz,
  kOther,  ///< not found, bad request, methods not allowed, preflight
  kCount,
};
const char* endpointName(Endpoint endpoint);

/// Error kinds counted apart from responses, the `kind` label of tessera_http_errors_total.
enum class ServeError : uint8_t {
  kParse,    ///< malformed request (answered 400/413/431 and closed)
  kTimeout,  ///< header, body, idle or send timeout
  kIo,       ///< socket errors other than a timeout or a clean close
  kArchive,  ///< an archive read, checksum or decode failed (answered 500)
  kTls,      ///< a TLS handshake failed (plain HTTP to the TLS port, a bad client hello)
  kCount,
};

/// Thread-safe and lock-free: every counter is an atomic, the (endpoint, status) table too, so
/// I/O threads recording responses never wait for one another.
class Metrics {
 public:
  /// Upper bounds of the latency histogram, in seconds.
  static constexpr std::array<double, 12> kLatencyBuckets = {
      0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5};

  void recordResponse(Endpoint endpoint, unsigned status, uint64_t body_bytes, double latency_s);
  void recordError(ServeError kind) { errors_[size_t(kind)].fetch_add(1); }
  void connectionOpened() {
    accepted_.fetch_add(1);
    open_.fetch_add(1);
  }
  void connectionClosed() { open_.fetch_sub(1); }
  void connectionRejected() { rejected_.fetch_add(1); }

  uint64_t requests() const { return requests_.load(); }
  uint64_t bodyBytes() const { return body_bytes_.load(); }
  uint64_t accepted() const { return accepted_.load(); }
  uint64_t rejected() const { return rejected_.load(); }
  uint64_t open() const { return open_.load(); }
  uint64_t errors(ServeError kind) const { return errors_[size_t(kind)].load(); }
  /// Responses whose status is in [100 * klass, 100 * klass + 100).
  uint64_t responsesOfClass(unsigned klass) const;

  /// The exposition text, cache figures included.
  std::string render(const TranscodeCache::Stats& cache) const;

 private:
  std::atomic<uint64_t> requests_{0}, body_bytes_{0}, accepted_{0}, rejected_{0}, open_{0};
  std::array<std::atomic<uint64_t>, size_t(ServeError::kCount)> errors_{};
  std::array<std::atomic<uint64_t>, kLatencyBuckets.size() + 1> latency_counts_{};
  std::atomic<uint64_t> latency_sum_us_{0};
  /// Responses by endpoint and status, statuses 100..599 (HTTP's range) at status - 100.
  static constexpr unsigned kFirstStatus = 100, kStatuses = 500;
  std::array<std::array<std::atomic<uint64_t>, kStatuses>, size_t(Endpoint::kCount)> by_status_{};
};

}  // namespace tessera::detail
