#pragma once
/// \file
/// A ByteSource over HTTP byte ranges (RFC 9110, section 14), on libcurl: an archive served by
/// `tessera serve`, nginx, a CDN, an S3-compatible object store, or any server that honours
/// `Range`. The runtime uses it unchanged; docs/remote.md has the failure behaviour and the
/// version (ETag) rule.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include <tessera/byte_source.h>
#include <tessera/result.h>

namespace tessera {

/// How an HTTP source talks to its server. The defaults suit a server on the internet.
struct HttpOptions {
  /// Time to set up a connection (DNS, TCP, TLS) before the attempt fails (and is retried).
  std::chrono::milliseconds connect_timeout{10'000};
  /// Longest one attempt of one request may take, connect included; 0 = no limit. A range
  /// of the loader is at most a few MiB, which this covers down to about 100 KiB/s.
  std::chrono::milliseconds request_timeout{60'000};
  /// An attempt that receives no byte for this long fails (and is retried): a stalled
  /// connection is noticed well before request_timeout. 0 = off.
  std::chrono::milliseconds stall_timeout{15'000};
  /// Attempts per request, the first included: connection errors, timeouts, truncated
  /// responses, 408, 429 and 5xx are retried; other 4xx and version changes never are.
  uint32_t max_attempts = 4;
  /// Backoff before retry n (1-based): retry_initial * 2^(n-1), at most retry_max, times a
  /// random factor in [0.5, 1] (jitter, so clients that failed together do not retry together).
  std::chrono::milliseconds retry_initial{100};
  std::chrono::milliseconds retry_max{5'000};
  /// A 429 or 503 with Retry-After waits what the server asks, but at most this.
  std::chrono::milliseconds retry_after_max{10'000};
  /// Connections to the server at most; more requests wait in libcurl's queue. Over HTTP/2
  /// requests are streams of one connection and this limits connections only. As many as
  /// the loader threads tuneForRemoteSource starts: over HTTP/1.1 one read per connection is
  /// in flight at a time, and on a long link the reads in flight set the rate.
  uint32_t max_connections = 16;
  /// Bytes fetched ahead on ByteSource::prefetch hints and held until a read takes them: the
  /// bound on that buffer. Hints beyond it are dropped, oldest unread data is evicted first.
  /// 0 ignores hints.
  uint64_t prefetch_buffer_bytes = 16u << 20;
  /// readMany asks for up to this many ranges in one request (`Range: bytes=a-b,c-d,...`,
  /// answered multipart/byteranges) where the server does that; 16 is `tessera serve`'s
  /// limit. A server that answers such a request with one range or the whole file is
  /// remembered and asked one range a request, without fetching more than asked. 1: never.
  uint32_t max_ranges_per_request = 16;
  /// Speak HTTP/2 from the first byte over plain http:// (h2c "prior knowledge"): only for a
  /// server known to accept it. Over https:// HTTP/2 is negotiated (ALPN) without this.
  bool http2_prior_knowledge = false;
  /// Offer HTTP/2 by ALPN over https:// (the server picks). False: HTTP/1.1 only, one request
  /// in flight per connection. LinkStats tells which version each connection spoke.
  bool http2 = true;
  /// Check the server's TLS certificate and host name (https://). Off only for tests and
  /// throwaway self-signed setups: anyone on the path can then read and alter the bytes.
  bool verify_tls = true;
  /// PEM file of the certificate authorities to trust for https:// instead of the system's
  /// (a private CA, or a self-signed server certificate itself). Empty: the system's store.
  std::string ca_file;
  /// Sent as User-Agent.
  std::string user_agent = "tessera/0.1";
  /// Sent as `Authorization: Bearer <token>` on every request when not empty: a token of
  /// `tessera serve --access` (docs/serve.md, "Access control"). Never in an error message.
  std::string bearer_token;
  /// Called when the server refuses a request with 401 or 403, with the URL it refused, to get
  /// a fresh one (typically a signed URL whose time ran out, signed again by the application);
  /// the request is retried with it at once and every later request uses it. An empty string,
  /// or no callback, fails the request. Runs on the source's I/O thread between transfers:
  /// it must be thread-safe, must not read from this source, and should be quick.
  std::function<std::string(const std::string& refused_url)> renew_url;
  /// AWS Signature Version 4 for object stores (S3 and S3-compatible: MinIO, Ceph RGW, R2...):
  /// when `access_key_id` is set, libcurl signs every request with these (region and service
  /// in the credential scope), and `session_token` is sent as x-amz-security-token. Never in an
  /// error message or a log. openS3Source fills it from the environment.
  struct AwsSigning {
    std::string access_key_id;
    std::string secret_access_key;
    std::string session_token;
    std::string region = "us-east-1";
    std::string service = "s3";
  } aws;
};

/// Opens `url` (http:// or https://) with one request: a GET of the first 16 KiB, which
/// yields the size (Content-Range), the version (the strong ETag, else Last-Modified) and
/// proof that ranges are honoured, and whose bytes the archive open then reads without a
/// request of its own. Fails (kNotFound on 404/410, kUnsupported when the server answers a
/// range with the whole file: "server does not honour byte ranges", kIo otherwise) naming
/// the URL and the cause.
///
/// Every later read asks for exactly its range with If-Match (or If-Unmodified-Since) on
/// that version and checks the answer's Content-Range and ETag: when the file on the server
/// changed, reads fail with kCorrupt "archive changed on the server (ETag was X, now Y)" and
/// keep failing; bytes of two versions are never mixed. Thread-safe: reads from many threads
/// run in parallel on keep-alive connections (HTTP/2 streams of one connection when the
/// server offers h2), driven by one I/O thread per source.
[[nodiscard]] Result<std::shared_ptr<ByteSource>> openHttpSource(const std::string& url,
                                                                 const HttpOptions& options = {});

/// Where an `s3://BUCKET/KEY` URL is fetched from and how, resolved as the AWS command-line
/// tools resolve it (docs/remote.md, "Object stores"):
/// - endpoint: `endpoint` if set, else $AWS_ENDPOINT_URL_S3, else $AWS_ENDPOINT_URL (then the
///   bucket goes in the path: http://host:port/BUCKET/KEY, as S3-compatible stores expect),
///   else AWS itself, the bucket in the host name (https://BUCKET.s3.REGION.amazonaws.com/KEY);
/// - region: `region`, else $AWS_REGION, else $AWS_DEFAULT_REGION, else the profile's
///   `region` in the config file ($AWS_CONFIG_FILE, ~/.aws/config), else us-east-1;
/// - credentials: $AWS_ACCESS_KEY_ID with $AWS_SECRET_ACCESS_KEY (and $AWS_SESSION_TOKEN),
///   else the profile ($AWS_PROFILE, else "default") in the credentials file
///   ($AWS_SHARED_CREDENTIALS_FILE, ~/.aws/credentials); none found: unsigned requests, which
///   public buckets answer.
struct S3Options {
  std::string endpoint;  ///< e.g. "http://127.0.0.1:9000"; empty: from the environment
  std::string region;    ///< empty: from the environment
  /// Everything else of the HTTP client (timeouts, retries, connections); its `aws` member is
  /// replaced by the credentials found.
  HttpOptions http;
};

/// The https:// (or the endpoint's http://) URL an `s3://` URL resolves to, with the signing
/// options, without opening it. Fails (kInvalidArgument) on a URL without a bucket or a key,
/// or a malformed endpoint, naming the URL; on an unreadable credentials file naming the file.
struct S3Target {
  std::string url;
  HttpOptions options;
};
[[nodiscard]] Result<S3Target> resolveS3Url(const std::string& s3_url,
                                            const S3Options& options = {});

/// Opens an archive in an object store: resolveS3Url, then openHttpSource. Ranges, the version
/// rule (ETag) and the retries are the HTTP source's; a 403 names the access key id used (never
/// the secret) and where it came from.
[[nodiscard]] Result<std::shared_ptr<ByteSource>> openS3Source(const std::string& s3_url,
                                                               const S3Options& options = {});

}  // namespace tessera
