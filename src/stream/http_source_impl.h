#pragma once
// The HTTP byte source's internals, shared by its two halves: http_source.cpp (what the
// loader threads call: reads, fetch-ahead, waiting) and http_io_thread.cpp (the one I/O thread
// that drives libcurl, and libcurl's callbacks). Remote streaming as in Marvie & Bouatouch,
// "Remote rendering of massively textured 3D scenes through progressive texture maps": the
// client asks for the pieces a view needs, cancels those that left it, and never trusts bytes
// of another version of the file.

#include <tessera/http_source.h>

#include "content_range.h"

#include <curl/curl.h>

#include <atomic>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <thread>
#include <vector>

namespace tessera::detail {

using Clock = std::chrono::steady_clock;

/// The open's probe: what Archive::open reads first (docs/format.md, the header region).
inline constexpr uint64_t kOpenBytes = 16384;
/// Samples LinkStats::recent keeps.
inline constexpr size_t kRecentSamples = 64;
/// How often the I/O thread looks at the cancel flags of requests that have one: the bound on
/// how long a cancelled read keeps the link busy when no byte arrives to run curl's callback.
inline constexpr int kCancelPollMs = 10;
/// Room for a multipart part's delimiter and headers (about 110 bytes from nginx and `tessera
/// serve`) in the body cap of a multi-range request.
inline constexpr uint64_t kMultipartPartOverheadBytes = 256;
/// The most range bytes one multi-range request asks for (its body is buffered).
inline constexpr uint64_t kMultiRangeMaxBytes = 16u << 20;
/// How often the I/O thread looks for stalled transfers while any is in flight.
inline constexpr int kStallPollMs = 100;

/// ASCII lower case, for URL schemes and header names.
inline std::string lowercase(std::string text) {
  for (char& c : text) c = char(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

/// Why our own callbacks stopped a transfer.
enum class Fault {
  kNone,
  kWholeFile,  ///< 200 to a range request
  kBadRange,   ///< a 206 whose Content-Range is not what was asked
  kChanged,    ///< the answer carries another version's ETag or size
  kTooLong,    ///< more body bytes than the range
  kCancelled,  ///< the reader's cancel flag
  kStalled,    ///< no byte for stall_timeout
  /// A request of several ranges answered by a single range that does not hold them all, or
  /// by 200: the server does not do multi-range requests (the reads fall back to one each).
  kMultiRangeRefused,
};

struct PrefetchEntry;
class HttpSource;

/// One request, from submission to completion, with its attempts. Fields above `done` are
/// the I/O thread's while the request is in flight; `done` and `result` are guarded by the
/// source's mutex and are the caller's after `done`.
struct Transfer {
  enum class Kind { kProbe, kRead, kHeadAfterChange };
  Kind kind = Kind::kRead;
  uint64_t offset_bytes = 0;
  uint64_t length_bytes = 0;  ///< for the probe: at most kOpenBytes, then what was received
  uint8_t* out = nullptr;
  const std::atomic<bool>* cancel = nullptr;
  std::shared_ptr<PrefetchEntry> prefetch;  ///< set for fetch-ahead requests
  const HttpSource* source = nullptr;
  /// A multi-range request: the ranges (ascending, apart), each with its own `out`; then
  /// offset_bytes/length_bytes span them all (for messages) and `out` is unused. The body is
  /// buffered in `body`, at most `body_cap` bytes, and split when complete.
  std::vector<ByteRange> parts;
  uint64_t body_cap = 0;
  std::vector<uint8_t> body;
  std::string boundary;  ///< of a multipart answer; empty for a single range holding all parts
  ContentRange single;   ///< a single-range answer's range
  bool multi_refused = false;  ///< completed with kMultiRangeRefused: read the parts one by one
  /// A multi-range request that completed: per part, empty when its bytes were delivered,
  /// else why not (no part of the answer holds it, or the answer broke off before it).
  std::vector<std::string> part_errors;

  // Per attempt.
  uint32_t attempt = 0;
  Clock::time_point not_before{};
  long status = 0;
  std::string status_text;
  std::string content_range, content_type, etag, last_modified, retry_after;
  bool body_started = false;
  bool request_sent = false;          ///< out of libcurl's queue and connected: stalls count
  Clock::time_point last_activity{};  ///< when the request went out, or its latest byte
  uint64_t received = 0;
  uint64_t wire_bytes = 0;  ///< every body byte received in this attempt, for the counters
  Fault fault = Fault::kNone;
  std::string fault_detail;
  char curl_error[CURL_ERROR_SIZE] = {};
  curl_slist* headers = nullptr;
  CURL* easy = nullptr;
  uint64_t probe_total = 0;  ///< the probe: the file size
  Error change_error;        ///< kHeadAfterChange: the message, completed with the HEAD's version

  bool renewed = false;  ///< the URL was renewed for this request already (HttpOptions::renew_url)

  bool done = false;
  Result<void> result;
};

/// Bytes fetched ahead on a prefetch hint. `bytes` is written by the I/O thread until `state`
/// leaves kInFlight (under the source's mutex), read by readers after.
struct PrefetchEntry {
  enum class State { kInFlight, kReady, kFailed };
  uint64_t offset_bytes = 0;
  std::vector<uint8_t> bytes;
  State state = State::kInFlight;
  uint64_t taken_bytes = 0;  ///< bytes readers copied out: the entry goes once all are taken
};

/// Thread-safe (ByteSource). The I/O thread owns libcurl; callers hand it transfers and wait.
class HttpSource final : public ByteSource {
 public:
  HttpSource(std::string url, HttpOptions options);

  ~HttpSource() override;

  /// The open's one request; fills size, version and the head bytes.
  Result<void> probe();

  uint64_t sizeBytes() const override { return size_bytes_; }
  const std::string& name() const override { return url_; }

  Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override;

  Result<void> readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                               const std::atomic<bool>& cancel) const override;

  // The runs go out at once, each its own request: they travel in parallel on the
  // connections (or HTTP/2 streams) instead of one round trip after another.
  Result<void> readMany(std::span<const ByteRange> ranges) const override;

  // The ranges in as few multi-range requests as the server allows (one range a request,
  // all at once, where it does not do them), each range with its own result.
  std::vector<Result<void>> readEach(std::span<const ByteRange> ranges,
                                     const std::atomic<bool>& cancel) const override;

  bool readsRangesTogether() const override { return true; }

  // Fetch-ahead into a bounded buffer that the following reads find (docs/remote.md).
  uint64_t prefetch(std::span<const ByteRange> ranges) const override;

  std::optional<LinkStats> linkStats() const override;

 private:
  Result<void> checkBounds(uint64_t offset_bytes, uint64_t length_bytes) const;

  Result<void> readRange(uint64_t offset_bytes, std::span<uint8_t> out,
                         const std::atomic<bool>* cancel) const;

  Unexpected cancelledError(uint64_t offset_bytes, std::span<uint8_t> out) const;

  Result<void> changedError() const;

  /// Copies the range from the head bytes or fetched-ahead data when they hold all of it,
  /// waiting for a fetch still on its way. Ok(true) when copied, Ok(false) when the read must
  /// make its own request, an error when it was cancelled while waiting.
  Result<bool> takeBuffered(uint64_t offset_bytes, std::span<uint8_t> out,
                            const std::atomic<bool>* cancel) const;

  bool coveredLocked(uint64_t offset_bytes, uint64_t length_bytes) const;

  void dropLocked(std::list<std::shared_ptr<PrefetchEntry>>::iterator it) const;

  void submit(const std::vector<std::shared_ptr<Transfer>>& transfers) const;

  Result<void> wait(const Transfer& transfer) const;

  Result<void> run(const std::shared_ptr<Transfer>& transfer) const;

  /// Fetches the ranges (ascending, apart, none buffered): several to a request while the
  /// server does multi-range requests, else one each, all at once. A refused multi-range
  /// request is remembered and its ranges fetched again one by one. Result i is range i's;
  /// `cancel` (may be null) abandons the requests still on the wire.
  std::vector<Result<void>> fetchRanges(std::span<const ByteRange> wanted,
                                        const std::atomic<bool>* cancel) const;

  // ---- The I/O thread ----

  void ioLoop();

  Error cancelledOf(const Transfer& transfer) const;

  static std::string rangeText(const Transfer& transfer);

  CURL* takeEasy();

  void startAttempt(Transfer& transfer);

  /// Takes the handle out of the multi and back to the pool (the connection stays cached).
  void stopAttempt(Transfer& transfer);
  /// Adds AWS Signature Version 4 to an attempt (HttpOptions::aws).
  void signForAws(CURL* easy, Transfer& transfer);

  /// After one attempt: completes the transfer, or returns true to retry it (not_before set).
  bool finishAttempt(Transfer& transfer, CURLcode code, std::mt19937_64& random);

  /// Schedules another attempt after a jittered exponential backoff (or the server's
  /// Retry-After, capped) and returns true; after max_attempts completes the transfer with
  /// `code` and `cause` and returns false.
  bool retryOrFail(Transfer& transfer, ErrorCode code, const std::string& what,
                   const std::string& cause, std::chrono::milliseconds server_wait,
                   std::mt19937_64& random);

  /// The HEAD asked by beginChangeReport answered: fails the source and the transfer with the
  /// change, naming the version the server has now.
  void finishChangeReport(Transfer& transfer);

  /// An attempt the callbacks marked with a fault: cancelled, stalled (retried), another
  /// version (change report), the whole file or a wrong range. finishAttempt's result.
  bool finishFault(Transfer& transfer, const std::string& what, std::mt19937_64& random);

  /// An attempt libcurl failed: retried when the error may pass (a truncated body, a timeout,
  /// a refused connection), else completed with it. finishAttempt's result.
  bool finishCurlError(Transfer& transfer, CURLcode code, const std::string& what,
                       std::mt19937_64& random);

  /// An attempt answered by the server: a complete 206 (its timing recorded), a change (412),
  /// 416, not found, a retryable status or a failure. finishAttempt's result.
  bool finishResponse(Transfer& transfer, const std::string& what, double seconds,
                      double first_byte_seconds, std::mt19937_64& random);

  /// A 416: an empty file when probing, a file that shrank when reading, else a failure.
  /// 401/403: renews the URL once through HttpOptions::renew_url (true: retry), else fails.
  bool finishRefused(Transfer& transfer, const std::string& what, const std::string& status_line);
  bool finishUnsatisfiable(Transfer& transfer, const std::string& what,
                           const std::string& status_line);

  std::chrono::milliseconds retryAfter(const Transfer& transfer) const;

  /// The file changed: asks the server (HEAD) for its version now, for the message; the
  /// transfer completes with the error once that answer is in.
  void beginChangeReport(Transfer& transfer, const std::string& detail);

  void setChanged(const Error& error);

  void recordSample(const Transfer& transfer, double seconds, double first_byte_seconds);

  void complete(Transfer& transfer, Result<void> result, bool is_error);

  /// At a 206's first body byte, its headers all in: is this the range asked, of the version
  /// opened? Sets the fault and returns false when not.
  bool acceptResponse(Transfer& transfer) const;

  /// acceptResponse for a multi-range request: a multipart body, or one range holding every
  /// part (within the body cap); anything else is kMultiRangeRefused.
  bool acceptMultiResponse(Transfer& transfer, const ContentRange& range) const;

  /// onBody for a multi-range request: buffers the body, stopping it past body_cap.
  static size_t bufferMultiBody(Transfer& transfer, const char* data, size_t bytes);

  /// A complete 206 to a multi-range request: copies each part to its reader's buffer after
  /// checking the body's ranges against those asked. Empty on success, else what is wrong.
  std::string scatterMultiBody(Transfer& transfer) const;

  // ---- libcurl callbacks (on the I/O thread) ----

  static size_t onHeader(char* data, size_t size, size_t count, void* user);

  static size_t onBody(char* data, size_t size, size_t count, void* user);

  static int onProgress(void* user, curl_off_t, curl_off_t, curl_off_t, curl_off_t);

  const std::string url_;
  /// The URL requests go to: url_ until HttpOptions::renew_url replaces it. The I/O thread's.
  std::string request_url_;
  const HttpOptions options_;
  // Set by probe() before the source is shared, constant after.
  uint64_t size_bytes_ = 0;
  std::vector<uint8_t> head_;  ///< the file's first bytes, from the probe
  std::string etag_;           ///< the strong ETag at open, or empty
  std::string last_modified_;  ///< Last-Modified at open when there is no strong ETag

  CURLM* multi_ = nullptr;        ///< the I/O thread's (curl_multi_wakeup from any thread)
  std::vector<CURL*> idle_easy_;  ///< the I/O thread's pool of handles between requests
  std::thread io_thread_;

  /// Guards everything below, and every Transfer's done/result and PrefetchEntry's state.
  /// Taken last: nothing is locked while holding it.
  mutable std::mutex mutex_;
  mutable std::condition_variable done_;  ///< a transfer completed (or a fetch-ahead landed)
  bool stopping_ = false;
  mutable std::vector<std::shared_ptr<Transfer>> submitted_;      ///< waiting for the I/O thread
  mutable std::list<std::shared_ptr<PrefetchEntry>> prefetched_;  ///< oldest first
  mutable uint64_t prefetch_bytes_ = 0;  ///< sum of prefetched_ sizes, <= prefetch_buffer_bytes
  /// Set once the file changed on the server: every later read fails with it, so no reader
  /// gets bytes of the new version under the old one's directory.
  Error changed_;
  /// Set once the server refused a multi-range request: from then on every range is a
  /// request of its own (per source, so per server and file).
  mutable std::atomic<bool> multi_range_refused_{false};
  mutable LinkStats stats_;  ///< totals (recent kept apart)
  mutable std::deque<LinkSample> recent_;
};

}  // namespace tessera::detail
