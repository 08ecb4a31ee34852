#pragma once
/// \file
/// `TileServer`: an asynchronous HTTP/1.1 server (Boost.Beast over Asio) for Tessera archives.
/// It serves stored tiles, the archive files themselves with RFC 9110 byte ranges, Deep Zoom
/// and XYZ endpoints transcoded to PNG or JPEG, Prometheus metrics and the embedded web
/// viewer. The endpoints, limits and status codes are specified in docs/serve.md.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <tessera/result.h>

namespace tessera {

/// Everything `tessera serve` can set. Defaults are the CLI's defaults.
struct ServeOptions {
  /// Archives (`.tess` files), folders of them (every `.tess` inside, not recursive), or
  /// `s3://BUCKET/KEY` URLs of archives in an object store (tessera/http_source.h,
  /// openS3Source: endpoint, region and credentials from the environment). Each archive is
  /// named by its file (or key) stem, which must match [A-Za-z0-9._-]+ and be unique.
  std::vector<std::string> paths;
  std::string bind_address = "127.0.0.1";  ///< IPv4 or IPv6 literal
  uint16_t port = 8080;                    ///< 0 picks an ephemeral port; see TileServer::port()
  uint32_t threads = 0;                    ///< I/O threads; 0 = hardware concurrency
  uint32_t max_connections = 10000;        ///< connections beyond this are closed on accept
  uint32_t header_timeout_ms = 10000;      ///< from a request's first byte to its complete header
  uint32_t body_timeout_ms = 10000;        ///< to receive a request body
  uint32_t idle_timeout_ms = 60000;        ///< a kept-alive connection waiting for its next request
  uint32_t send_timeout_ms = 60000;        ///< a response write making no progress
  uint32_t header_limit_bytes = 8192;      ///< request line + header fields; larger -> 431
  uint32_t body_limit_bytes = 65536;       ///< request body; larger -> 413
  uint32_t max_ranges = 16;                ///< byte ranges per request; more -> 416
  uint64_t transcode_cache_bytes = 64ull << 20;  ///< LRU of transcoded tiles, by bytes
  int jpeg_quality = 85;                         ///< for transcoded JPEG tiles
  /// Access-Control-Allow-Origin value ("*" or an origin); empty sends no CORS headers.
  std::string cors_origin;
  /// Access log: a path, "-" for stdout, empty for none. One line per request; the `sig`
  /// of a signed URL is logged as "REDACTED".
  std::string access_log;
  /// Access file (JSON, docs/serve.md "Access control"): public archives, bearer tokens and
  /// URL-signing keys per archive or pattern, per-archive CORS origins, a per-client rate
  /// limit. Empty: every archive is readable by every client that reaches the port.
  std::string access_file;
  /// TLS: the certificate chain (PEM: the server's certificate, then any intermediates) and
  /// its private key (PEM, unencrypted). Both set: every connection speaks TLS 1.2 or 1.3,
  /// HTTP/1.1 inside; both empty: plain HTTP. TileServer::reloadTls reads them again.
  std::string tls_cert_file;
  std::string tls_key_file;
  /// Called once by `start`, on the calling thread, after the socket is bound and before any
  /// connection is accepted, with the bound address and port: the CLI prints its "listening
  /// on" line here, so that line precedes every access log line on stdout. May be empty.
  std::function<void(const std::string& address, uint16_t port)> on_listening;
};

/// The query string ("key=ID&expires=T[&archive=NAME][&range=A-B]&sig=HEX") of a signed URL
/// that `tessera serve --access ACCESS_FILE` accepts until `expires_unix_s`: for one request
/// path (`scope` "/earth.tess", "/earth/info.json", ...) or for every route of an archive
/// (`scope` "archive:earth"), and when `range` ("A-B") is set, for requests whose byte ranges
/// all lie inside it. The secret is key `key_id`'s in the access file; the algorithm
/// (HMAC-SHA256) is in docs/serve.md so other languages can sign too. Errors name the file or
/// the key, never the secret.
[[nodiscard]] Result<std::string> signServeQuery(const std::string& access_file,
                                                 const std::string& key_id,
                                                 const std::string& scope, int64_t expires_unix_s,
                                                 const std::string& range = {});

/// Counters since start, for tests and the CLI. All values are monotonic except the gauges
/// marked so.
struct ServeStats {
  uint64_t requests = 0;
  uint64_t responses_2xx = 0;
  uint64_t responses_3xx = 0;
  uint64_t responses_4xx = 0;
  uint64_t responses_5xx = 0;
  uint64_t body_bytes_sent = 0;
  uint64_t connections_accepted = 0;
  uint64_t connections_rejected = 0;  ///< over max_connections or the file descriptor limit
  uint64_t connections_open = 0;      ///< gauge
  uint64_t timeouts = 0;              ///< connections closed by a header/body/idle/send timeout
  uint64_t parse_errors = 0;          ///< malformed requests answered 4xx and closed
  uint64_t tls_handshake_errors = 0;  ///< connections closed in a failed TLS handshake
  uint64_t transcode_cache_hits = 0;
  uint64_t transcode_cache_misses = 0;
  uint64_t transcode_cache_bytes = 0;    ///< gauge
  uint64_t transcode_cache_entries = 0;  ///< gauge
};

/// The server. `start` opens every archive, binds and starts the I/O threads; `stop` shuts
/// down gracefully. Thread-safe: `port`, `stats` and `stop` may be called from any thread.
class TileServer {
 public:
  /// Opens the archives named by `options.paths` and starts listening. Fails naming the file
  /// (not an archive, bad or duplicate name, empty folder; a TLS certificate or key that is
  /// missing, not PEM or not a pair) or the address (cannot bind).
  [[nodiscard]] static Result<std::unique_ptr<TileServer>> start(const ServeOptions& options);

  /// Stops if still running.
  ~TileServer();
  TileServer(const TileServer&) = delete;
  TileServer& operator=(const TileServer&) = delete;

  /// The bound port (the ephemeral one when options.port was 0).
  uint16_t port() const;
  /// The bound address as text, e.g. "127.0.0.1".
  std::string address() const;
  /// Names of the archives served, sorted.
  std::vector<std::string> archiveNames() const;
  ServeStats stats() const;
  /// True when serving TLS (ServeOptions::tls_cert_file).
  bool tls() const;
  /// Reads the certificate and key files again and hands the result to connections accepted
  /// from then on; connections already open keep theirs. On an error (naming the file) the
  /// previous certificate stays in use. Fails when not serving TLS. Thread-safe; `tessera
  /// serve` calls it on SIGHUP.
  [[nodiscard]] Result<void> reloadTls();

  /// Stops accepting, closes idle connections, lets responses in flight finish for up to
  /// `grace_ms`, then closes the rest and joins the threads. Idempotent.
  void stop(uint32_t grace_ms = 5000);

  struct Impl;

 private:
  explicit TileServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
