#include "metrics.h"

#include <fmt/format.h>

namespace tessera::detail {

const char* endpointName(Endpoint endpoint) {
  switch (endpoint) {
    case Endpoint::kViewer: return "viewer";
    case Endpoint::kHealth: return "healthz";
    case Endpoint::kMetrics: return "metrics";
    case Endpoint::kArchives: return "archives";
    case Endpoint::kInfo: return "info";
    case Endpoint::kTile: return "tile";
    case Endpoint::kArchiveFile: return "archive_file";
    case Endpoint::kDzi: return "dzi";
    case Endpoint::kDziTile: return "dzi_tile";
    case Endpoint::kXyz: return "xyz";
    default: return "other";
  }
}

namespace {

const char* errorName(ServeError kind) {
  switch (kind) {
    case ServeError::kParse: return "parse";
    case ServeError::kTimeout: return "timeout";
    case ServeError::kIo: return "io";
    case ServeError::kTls: return "tls";
    default: return "archive";
  }
}

}  // namespace

void Metrics::recordResponse(Endpoint endpoint, unsigned status, uint64_t body_bytes,
                             double latency_s) {
  requests_.fetch_add(1);
  body_bytes_.fetch_add(body_bytes);
  size_t bucket = 0;
  while (bucket < kLatencyBuckets.size() && latency_s > kLatencyBuckets[bucket]) ++bucket;
  latency_counts_[bucket].fetch_add(1);
  latency_sum_us_.fetch_add(uint64_t(latency_s * 1e6));
  if (status >= kFirstStatus && status < kFirstStatus + kStatuses)
    by_status_[size_t(endpoint)][status - kFirstStatus].fetch_add(1, std::memory_order_relaxed);
}

uint64_t Metrics::responsesOfClass(unsigned klass) const {
  uint64_t total = 0;
  if (klass < 1 || klass > 5) return 0;
  for (const auto& statuses : by_status_)
    for (unsigned status = klass * 100; status < klass * 100 + 100; ++status)
      total += statuses[status - kFirstStatus].load(std::memory_order_relaxed);
  return total;
}

std::string Metrics::render(const TranscodeCache::Stats& cache) const {
  std::string out;
  auto counter = [&](const char* name, const char* help, uint64_t value) {
    out += fmt::format("# HELP {0} {1}\n# TYPE {0} counter\n{0} {2}\n", name, help, value);
  };
  auto gauge = [&](const char* name, const char* help, uint64_t value) {
    out += fmt::format("# HELP {0} {1}\n# TYPE {0} gauge\n{0} {2}\n", name, help, value);
  };
  out +=
      "# HELP tessera_http_requests_total HTTP responses sent, by endpoint and status.\n"
      "# TYPE tessera_http_requests_total counter\n";
  for (size_t endpoint = 0; endpoint < by_status_.size(); ++endpoint)
    for (unsigned i = 0; i < kStatuses; ++i)
      if (const uint64_t count = by_status_[endpoint][i].load(std::memory_order_relaxed))
        out += fmt::format("tessera_http_requests_total{{endpoint=\"{}\",status=\"{}\"}} {}\n",
                           endpointName(Endpoint(endpoint)), i + kFirstStatus, count);
  counter("tessera_http_response_body_bytes_total", "Response body bytes sent.",
          body_bytes_.load());
  out +=
      "# HELP tessera_http_request_duration_seconds From a request's complete header to its "
      "response's last byte written.\n"
      "# TYPE tessera_http_request_duration_seconds histogram\n";
  uint64_t cumulative = 0;
  for (size_t i = 0; i < kLatencyBuckets.size(); ++i) {
    cumulative += latency_counts_[i].load();
    out += fmt::format("tessera_http_request_duration_seconds_bucket{{le=\"{}\"}} {}\n",
                       kLatencyBuckets[i], cumulative);
  }
  cumulative += latency_counts_[kLatencyBuckets.size()].load();
  out +=
      fmt::format("tessera_http_request_duration_seconds_bucket{{le=\"+Inf\"}} {}\n", cumulative);
  out += fmt::format("tessera_http_request_duration_seconds_sum {:.6f}\n",
                     double(latency_sum_us_.load()) / 1e6);
  out += fmt::format("tessera_http_request_duration_seconds_count {}\n", cumulative);
  counter("tessera_http_connections_accepted_total", "TCP connections accepted.", accepted_.load());
  counter("tessera_http_connections_rejected_total",
          "TCP connections closed on accept because the connection limit was reached.",
          rejected_.load());
  gauge("tessera_http_connections_open", "TCP connections open now.", open_.load());
  out +=
      "# HELP tessera_http_errors_total Failed requests and connections, by kind.\n"
      "# TYPE tessera_http_errors_total counter\n";
  for (size_t i = 0; i < size_t(ServeError::kCount); ++i)
    out += fmt::format("tessera_http_errors_total{{kind=\"{}\"}} {}\n", errorName(ServeError(i)),
                       errors_[i].load());
  counter("tessera_transcode_cache_hits_total", "Transcoded tiles served from the cache.",
          cache.hits);
  counter("tessera_transcode_cache_misses_total", "Transcoded tiles that had to be encoded.",
          cache.misses);
  counter("tessera_transcode_cache_evictions_total", "Transcoded tiles evicted (LRU).",
          cache.evictions);
  gauge("tessera_transcode_cache_bytes", "Bytes of transcoded tiles held.", cache.bytes);
  gauge("tessera_transcode_cache_entries", "Transcoded tiles held.", cache.entries);
  gauge("tessera_transcode_cache_capacity_bytes", "The cache's byte budget.", cache.capacity_bytes);
  return out;
}

}  // namespace tessera::detail
