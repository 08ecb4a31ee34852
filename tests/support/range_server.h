#pragma once
// A small HTTP/1.1 server of one file's byte ranges, for tests of clients: it answers each
// request as a plan says (serve, an error status, a truncated or stalled body, the whole
// file, a wrong range), so retries, version checks and cancellation are tested
// deterministically. Keep-alive; one thread per connection.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tessera::test {

/// How the server answers one request.
struct RangeReply {
  enum class Kind {
    kServe,       ///< honour Range (206) and If-Match / If-Range as RFC 9110 says
    kStatus,      ///< `status` with a short body (and Retry-After when set)
    kWholeFile,   ///< 200 with the whole file, whatever was asked
    kTruncate,    ///< the 206's headers, then half its body, then close the connection
    kStall,       ///< the 206's headers and half its body, then nothing until the client leaves
    kWrongRange,  ///< a 206 one byte off what was asked
    /// A request of several ranges answered multipart/byteranges, its parts in reverse order
    /// (a single range is served as kServe). The kinds after it, all multipart, break it.
    kMultipart,
    kMultipartWrongRange,  ///< each part labelled one byte off the bytes it carries
    kMultipartOversized,   ///< a 1 MiB preamble before the parts
    /// kMultipart with one bad part, the first range asked (the others are right): labelled
    /// one byte off, or with its bytes flipped under the right label.
    kMultipartFirstMislabelled,
    kMultipartFirstCorrupt,
  };
  Kind kind = Kind::kServe;
  int status = 200;
  std::string retry_after;
};

/// What the server saw of one request.
struct SeenRequest {
  std::string method;
  std::string range;     ///< the Range header, or empty
  std::string if_match;  ///< If-Match, or empty
  std::string if_range;  ///< If-Range, or empty
  std::string if_unmodified_since;
  /// 1 + the highest round of the requests answered before this one came (1 when none was):
  /// the round trips on the client's critical path to it, at most (a request sent after an
  /// answer it did not wait for also counts as one round later).
  uint32_t round = 1;
};

/// Thread-safe.
class RangeServer {
 public:
  /// Serves `bytes` on 127.0.0.1 at an ephemeral port. `etag` empty: no ETag header (then
  /// Last-Modified is sent).
  RangeServer(std::vector<uint8_t> bytes, std::string etag);
  ~RangeServer();

  std::string url() const;
  /// Answers request n (0-based, counting every request) by `plan(n)`; the default serves.
  void setPlan(std::function<RangeReply(uint64_t)> plan);
  /// A new version of the file: new bytes and ETag. `honour_conditionals` false makes the
  /// server ignore If-Match and If-Range (a broken cache in the way).
  void replace(std::vector<uint8_t> bytes, std::string etag, bool honour_conditionals);
  std::vector<SeenRequest> seen() const;
  /// Every answer leaves `latency` after its request came (a long link's round trip), so the
  /// requests a client sends together all come before any is answered. Default 0.
  void setLatency(std::chrono::milliseconds latency);
  /// Blocks until a kStall reply has sent its partial body.
  void waitStalled();

 private:
  void acceptLoop();
  void serve(int fd);
  /// Answers one request, `index` its place in seen_; false closes the connection.
  bool handle(int fd, const SeenRequest& seen, size_t& index);
  bool sendMultipart(int fd, RangeReply::Kind kind, const std::string& range,
                     const std::vector<uint8_t>& bytes, const std::string& validator);

  int listen_fd_ = -1;
  uint16_t port_ = 0;
  std::thread acceptor_;
  mutable std::mutex mutex_;  ///< guards everything below
  std::condition_variable changed_;
  std::vector<uint8_t> bytes_;
  std::string etag_;
  bool honour_conditionals_ = true;
  std::function<RangeReply(uint64_t)> plan_;
  std::vector<SeenRequest> seen_;
  uint32_t answered_round_max_ = 0;  ///< the highest round of the requests answered
  std::chrono::milliseconds latency_{0};
  std::vector<std::thread> connections_;
  std::vector<int> connection_fds_;
  bool stalled_ = false;
  bool stopping_ = false;
};

}  // namespace tessera::test
