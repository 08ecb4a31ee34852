// The HTTP byte source: ranged GETs on libcurl, one multi handle driven by one I/O thread per
// source, so the reads of many loader threads share keep-alive connections (and HTTP/2
// streams) instead of each opening its own. Remote streaming as in Marvie & Bouatouch,
// "Remote rendering of massively textured 3D scenes through progressive texture maps": the
// client asks for the pieces a view needs, cancels those that left it, and never trusts bytes
// of another version of the file.
#include <tessera/http_source.h>

#include <curl/curl.h>

#include <algorithm>
#include <cctype>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <list>
#include <mutex>
#include <random>
#include <thread>

#include <fmt/format.h>

#include "format/read_plan.h"

namespace tessera {

namespace {

using Clock = std::chrono::steady_clock;

/// The open's probe: what Archive::open reads first (docs/format.md, the header region).
constexpr uint64_t kOpenBytes = 16384;
/// Samples LinkStats::recent keeps.
constexpr size_t kRecentSamples = 64;
/// How often the I/O thread looks at the cancel flags of requests that have one: the bound on
/// how long a cancelled read keeps the link busy when no byte arrives to run curl's callback.
constexpr int kCancelPollMs = 10;
/// How often the I/O thread looks for stalled transfers while any is in flight.
constexpr int kStallPollMs = 100;

void initCurlOnce() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

std::string lowercase(std::string text) {
  for (char& c : text) c = char(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

std::string trim(std::string_view text) {
  size_t begin = 0, end = text.size();
  while (begin < end && std::isspace(static_cast<unsigned char>(text[begin]))) ++begin;
  while (end > begin && std::isspace(static_cast<unsigned char>(text[end - 1]))) --end;
  return std::string(text.substr(begin, end - begin));
}

/// "bytes A-B/T" (T may be "*"): the range a 206 carries, or the size a 416 reports
/// ("bytes */T", has_range false).
struct ContentRange {
  bool has_range = false;
  uint64_t first = 0, last = 0;
  bool has_total = false;
  uint64_t total = 0;
};

bool parseUint(std::string_view text, uint64_t& out) {
  if (text.empty() || text.size() > 19) return false;
  uint64_t value = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return false;
    value = value * 10 + uint64_t(c - '0');
  }
  out = value;
  return true;
}

bool parseContentRange(const std::string& header, ContentRange& out) {
  std::string_view text = header;
  if (lowercase(std::string(text.substr(0, 6))) != "bytes ") return false;
  text.remove_prefix(6);
  const size_t slash = text.find('/');
  if (slash == std::string_view::npos) return false;
  std::string_view range = text.substr(0, slash), total = text.substr(slash + 1);
  if (total == "*") {
    out.has_total = false;
  } else {
    if (!parseUint(total, out.total)) return false;
    out.has_total = true;
  }
  if (range == "*") {
    out.has_range = false;
    return out.has_total;
  }
  const size_t dash = range.find('-');
  if (dash == std::string_view::npos) return false;
  if (!parseUint(range.substr(0, dash), out.first) || !parseUint(range.substr(dash + 1), out.last))
    return false;
  out.has_range = out.first <= out.last;
  return out.has_range;
}

/// Strong comparison (RFC 9110, 8.8.3.2): weak tags never match.
bool strongEtag(const std::string& etag) {
  return !etag.empty() && etag.rfind("W/", 0) != 0;
}

/// Statuses worth another attempt: the server or a proxy may answer the next one.
bool retryableStatus(long status) {
  return status == 408 || status == 429 || (status >= 500 && status <= 599);
}

bool retryableCurlCode(CURLcode code) {
  switch (code) {
    case CURLE_COULDNT_CONNECT:
    case CURLE_OPERATION_TIMEDOUT:
    case CURLE_PARTIAL_FILE:
    case CURLE_RECV_ERROR:
    case CURLE_SEND_ERROR:
    case CURLE_GOT_NOTHING:
    case CURLE_HTTP2:
    case CURLE_HTTP2_STREAM:
    case CURLE_SSL_CONNECT_ERROR: return true;
    default: return false;
  }
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

  // Per attempt.
  uint32_t attempt = 0;
  Clock::time_point not_before{};
  long status = 0;
  std::string status_text;
  std::string content_range, etag, last_modified, retry_after;
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
  HttpSource(std::string url, HttpOptions options)
      : url_(std::move(url)), options_(std::move(options)) {
    initCurlOnce();
    multi_ = curl_multi_init();
    curl_multi_setopt(multi_, CURLMOPT_PIPELINING, long(CURLPIPE_MULTIPLEX));
    curl_multi_setopt(multi_, CURLMOPT_MAX_HOST_CONNECTIONS, long(options_.max_connections));
    curl_multi_setopt(multi_, CURLMOPT_MAX_TOTAL_CONNECTIONS, long(options_.max_connections));
    curl_multi_setopt(multi_, CURLMOPT_MAXCONNECTS, long(options_.max_connections));
    io_thread_ = std::thread([this] { ioLoop(); });
  }

  ~HttpSource() override {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    curl_multi_wakeup(multi_);
    io_thread_.join();
    for (CURL* easy : idle_easy_) curl_easy_cleanup(easy);
    curl_multi_cleanup(multi_);
  }

  /// The open's one request; fills size, version and the head bytes.
  Result<void> probe() {
    head_.resize(kOpenBytes);
    auto transfer = std::make_shared<Transfer>();
    transfer->kind = Transfer::Kind::kProbe;
    transfer->length_bytes = kOpenBytes;
    transfer->out = head_.data();
    TESSERA_TRY(run(transfer));
    size_bytes_ = transfer->probe_total;
    head_.resize(transfer->received);
    if (strongEtag(transfer->etag))
      etag_ = transfer->etag;
    else
      last_modified_ = transfer->last_modified;
    return {};
  }

  uint64_t sizeBytes() const override { return size_bytes_; }
  const std::string& name() const override { return url_; }

  Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override {
    return readRange(offset_bytes, out, nullptr);
  }

  Result<void> readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                               const std::atomic<bool>& cancel) const override {
    return readRange(offset_bytes, out, &cancel);
  }

  // The runs go out at once, each its own request: they travel in parallel on the
  // connections (or HTTP/2 streams) instead of one round trip after another.
  Result<void> readMany(std::span<const ByteRange> ranges) const override {
    TESSERA_TRY(changedError());
    std::vector<detail::ReadRun> runs = detail::planReadRuns(ranges);
    std::vector<std::vector<uint8_t>> buffers(runs.size());
    std::vector<std::shared_ptr<Transfer>> transfers;
    for (size_t i = 0; i < runs.size(); ++i) {
      const detail::ReadRun& run = runs[i];
      TESSERA_TRY(checkBounds(run.offset_bytes, run.length_bytes));
      if (run.length_bytes == 0) continue;
      uint8_t* out = ranges[run.members[0]].out;
      if (run.members.size() > 1) {
        buffers[i].resize(run.length_bytes);
        out = buffers[i].data();
      }
      std::span<uint8_t> target(out, run.length_bytes);
      Result<bool> taken = takeBuffered(run.offset_bytes, target, nullptr);
      if (taken && *taken) continue;
      auto transfer = std::make_shared<Transfer>();
      transfer->offset_bytes = run.offset_bytes;
      transfer->length_bytes = run.length_bytes;
      transfer->out = out;
      transfers.push_back(transfer);
    }
    submit(transfers);
    Result<void> result;
    for (const auto& transfer : transfers) {
      Result<void> one = wait(*transfer);
      if (!one && result) result = std::move(one);
    }
    if (!result) return result;
    for (size_t i = 0; i < runs.size(); ++i)
      if (runs[i].members.size() > 1) detail::scatterRun(runs[i], ranges, buffers[i]);
    return {};
  }

  // Fetch-ahead into a bounded buffer that the following reads find (docs/remote.md).
  uint64_t prefetch(std::span<const ByteRange> ranges) const override {
    if (options_.prefetch_buffer_bytes == 0) return 0;
    std::vector<std::shared_ptr<Transfer>> transfers;
    uint64_t asked = 0;
    {
      std::lock_guard lock(mutex_);
      if (!changed_.message.empty()) return 0;
      for (const ByteRange& range : ranges) {
        if (range.offset_bytes >= size_bytes_ || range.length_bytes == 0) continue;
        const uint64_t length = std::min(range.length_bytes, size_bytes_ - range.offset_bytes);
        if (length > options_.prefetch_buffer_bytes) continue;
        if (coveredLocked(range.offset_bytes, length)) continue;
        // Oldest data no read took first: it belongs to tiles that were cancelled or read by
        // a request of their own.
        while (prefetch_bytes_ + length > options_.prefetch_buffer_bytes) {
          auto oldest = std::find_if(prefetched_.begin(), prefetched_.end(), [](const auto& e) {
            return e->state != PrefetchEntry::State::kInFlight;
          });
          if (oldest == prefetched_.end()) break;
          dropLocked(oldest);
        }
        if (prefetch_bytes_ + length > options_.prefetch_buffer_bytes) break;
        auto entry = std::make_shared<PrefetchEntry>();
        entry->offset_bytes = range.offset_bytes;
        entry->bytes.resize(length);
        prefetched_.push_back(entry);
        prefetch_bytes_ += length;
        auto transfer = std::make_shared<Transfer>();
        transfer->offset_bytes = range.offset_bytes;
        transfer->length_bytes = length;
        transfer->out = entry->bytes.data();
        transfer->prefetch = entry;
        transfers.push_back(std::move(transfer));
        asked += length;
      }
    }
    submit(transfers);
    return asked;
  }

  std::optional<LinkStats> linkStats() const override {
    std::lock_guard lock(mutex_);
    LinkStats stats = stats_;
    stats.recent.assign(recent_.begin(), recent_.end());
    return stats;
  }

 private:
  Result<void> checkBounds(uint64_t offset_bytes, uint64_t length_bytes) const {
    if (offset_bytes > size_bytes_ || length_bytes > size_bytes_ - offset_bytes)
      return fail(ErrorCode::kIo, fmt::format("{}: read [{}, +{}) past the end ({} bytes)", url_,
                                              offset_bytes, length_bytes, size_bytes_));
    return {};
  }

  Result<void> readRange(uint64_t offset_bytes, std::span<uint8_t> out,
                         const std::atomic<bool>* cancel) const {
    TESSERA_TRY(checkBounds(offset_bytes, out.size()));
    if (out.empty()) return {};
    if (cancel && cancel->load(std::memory_order_acquire)) return cancelledError(offset_bytes, out);
    if (Result<void> changed = changedError(); !changed) return changed;
    Result<bool> taken = takeBuffered(offset_bytes, out, cancel);
    if (!taken) return forwardError(taken);
    if (*taken) return {};
    auto transfer = std::make_shared<Transfer>();
    transfer->offset_bytes = offset_bytes;
    transfer->length_bytes = out.size();
    transfer->out = out.data();
    transfer->cancel = cancel;
    return run(transfer);
  }

  Unexpected cancelledError(uint64_t offset_bytes, std::span<uint8_t> out) const {
    {
      std::lock_guard lock(mutex_);
      ++stats_.cancelled;
    }
    return fail(ErrorCode::kCancelled, fmt::format("{}: read of bytes={}-{} cancelled", url_,
                                                   offset_bytes, offset_bytes + out.size() - 1));
  }

  Result<void> changedError() const {
    std::lock_guard lock(mutex_);
    if (changed_.message.empty()) return {};
    return Unexpected(changed_);
  }

  /// Copies the range from the head bytes or fetched-ahead data when they hold all of it,
  /// waiting for a fetch still on its way. Ok(true) when copied, Ok(false) when the read must
  /// make its own request, an error when it was cancelled while waiting.
  Result<bool> takeBuffered(uint64_t offset_bytes, std::span<uint8_t> out,
                            const std::atomic<bool>* cancel) const {
    if (offset_bytes + out.size() <= head_.size()) {
      std::memcpy(out.data(), head_.data() + offset_bytes, out.size());
      return true;
    }
    std::unique_lock lock(mutex_);
    for (;;) {
      auto it = std::find_if(prefetched_.begin(), prefetched_.end(), [&](const auto& e) {
        return e->offset_bytes <= offset_bytes &&
               offset_bytes + out.size() <= e->offset_bytes + e->bytes.size();
      });
      if (it == prefetched_.end()) return false;
      std::shared_ptr<PrefetchEntry> entry = *it;
      if (entry->state == PrefetchEntry::State::kFailed) return false;
      if (entry->state == PrefetchEntry::State::kReady) {
        std::memcpy(out.data(), entry->bytes.data() + (offset_bytes - entry->offset_bytes),
                    out.size());
        entry->taken_bytes += out.size();
        stats_.prefetch_hit_bytes += out.size();
        if (entry->taken_bytes >= entry->bytes.size()) dropLocked(it);
        return true;
      }
      // On its way: the I/O thread signals when it lands. A reader that may be cancelled
      // looks at its flag now and then; the fetch goes on for other readers.
      if (cancel) {
        if (cancel->load(std::memory_order_acquire)) {
          lock.unlock();
          return cancelledError(offset_bytes, out);
        }
        done_.wait_for(lock, std::chrono::milliseconds(kCancelPollMs));
      } else {
        done_.wait(lock);
      }
    }
  }

  bool coveredLocked(uint64_t offset_bytes, uint64_t length_bytes) const {
    if (offset_bytes + length_bytes <= head_.size()) return true;
    return std::any_of(prefetched_.begin(), prefetched_.end(), [&](const auto& e) {
      return e->state != PrefetchEntry::State::kFailed && e->offset_bytes <= offset_bytes &&
             offset_bytes + length_bytes <= e->offset_bytes + e->bytes.size();
    });
  }

  void dropLocked(std::list<std::shared_ptr<PrefetchEntry>>::iterator it) const {
    prefetch_bytes_ -= (*it)->bytes.size();
    prefetched_.erase(it);
  }

  void submit(const std::vector<std::shared_ptr<Transfer>>& transfers) const {
    if (transfers.empty()) return;
    {
      std::lock_guard lock(mutex_);
      for (const auto& transfer : transfers) submitted_.push_back(transfer);
    }
    curl_multi_wakeup(multi_);
  }

  Result<void> wait(const Transfer& transfer) const {
    std::unique_lock lock(mutex_);
    done_.wait(lock, [&] { return transfer.done; });
    return transfer.result;
  }

  Result<void> run(const std::shared_ptr<Transfer>& transfer) const {
    submit({transfer});
    return wait(*transfer);
  }

  // ---- The I/O thread ----

  void ioLoop() {
    std::vector<std::shared_ptr<Transfer>> active, waiting;
    std::mt19937_64 random{std::random_device{}()};
    for (;;) {
      {
        std::lock_guard lock(mutex_);
        if (stopping_) break;
        for (auto& transfer : submitted_) waiting.push_back(std::move(transfer));
        submitted_.clear();
      }
      const auto now = Clock::now();
      bool watch_cancel = false;
      for (auto it = waiting.begin(); it != waiting.end();) {
        const std::shared_ptr<Transfer>& transfer = *it;
        if (transfer->cancel && transfer->cancel->load(std::memory_order_acquire)) {
          complete(*transfer, Unexpected(cancelledOf(*transfer)), false);
          it = waiting.erase(it);
        } else if (transfer->not_before <= now) {
          startAttempt(*transfer);
          active.push_back(*it);
          it = waiting.erase(it);
        } else {
          ++it;
        }
      }
      for (auto it = active.begin(); it != active.end();) {
        Transfer& transfer = **it;
        if (transfer.cancel && transfer.cancel->load(std::memory_order_acquire)) {
          // Removing the handle closes the transfer now, whether or not bytes are arriving.
          stopAttempt(transfer);
          complete(transfer, Unexpected(cancelledOf(transfer)), false);
          it = active.erase(it);
          continue;
        }
        // Stall detection of our own: curl's low-speed limit averages over seconds, so a
        // transfer that stalls after a burst would look alive for several more.
        if (!transfer.request_sent) {
          // Time waiting in libcurl's queue for a connection is not a stall.
          curl_off_t sent_us = 0;
          curl_easy_getinfo(transfer.easy, CURLINFO_PRETRANSFER_TIME_T, &sent_us);
          if (sent_us > 0) {
            transfer.request_sent = true;
            transfer.last_activity = std::max(transfer.last_activity, now);
          }
        }
        if (transfer.request_sent && options_.stall_timeout.count() > 0 &&
            now - transfer.last_activity > options_.stall_timeout) {
          transfer.fault = Fault::kStalled;
          std::shared_ptr<Transfer> stalled = *it;
          it = active.erase(it);
          if (finishAttempt(*stalled, CURLE_OPERATION_TIMEDOUT, random)) waiting.push_back(stalled);
          continue;
        }
        watch_cancel |= transfer.cancel != nullptr;
        ++it;
      }
      {
        std::lock_guard lock(mutex_);
        stats_.in_flight = uint32_t(active.size());
      }
      int running = 0;
      curl_multi_perform(multi_, &running);
      int left = 0;
      while (CURLMsg* message = curl_multi_info_read(multi_, &left)) {
        if (message->msg != CURLMSG_DONE) continue;
        Transfer* finished = nullptr;
        curl_easy_getinfo(message->easy_handle, CURLINFO_PRIVATE, &finished);
        const CURLcode code = message->data.result;
        auto it = std::find_if(active.begin(), active.end(),
                               [&](const auto& t) { return t.get() == finished; });
        if (it == active.end()) continue;
        std::shared_ptr<Transfer> transfer = *it;
        active.erase(it);
        if (finishAttempt(*transfer, code, random)) waiting.push_back(transfer);
      }
      // Sleep until curl has work, a request is submitted (curl_multi_wakeup), a retry is
      // due, or (with cancellable requests about) the next look at their flags.
      int timeout_ms = 1000;
      const auto after = Clock::now();
      for (const auto& transfer : waiting) {
        watch_cancel |= transfer->cancel != nullptr;
        const int64_t due_ms =
            std::chrono::ceil<std::chrono::milliseconds>(transfer->not_before - after).count();
        timeout_ms = int(std::clamp<int64_t>(due_ms, 0, timeout_ms));
      }
      if (watch_cancel) timeout_ms = std::min(timeout_ms, kCancelPollMs);
      if (!active.empty() && options_.stall_timeout.count() > 0)
        timeout_ms = std::min(timeout_ms, kStallPollMs);
      curl_multi_poll(multi_, nullptr, 0, timeout_ms, nullptr);
    }
    // Closing: nothing waits for reads (the source's owner is gone), only fetch-aheads.
    for (const auto& transfer : active) {
      stopAttempt(*transfer);
      complete(*transfer, fail(ErrorCode::kCancelled, url_ + ": source closed"), false);
    }
    for (const auto& transfer : waiting)
      complete(*transfer, fail(ErrorCode::kCancelled, url_ + ": source closed"), false);
    std::lock_guard lock(mutex_);
    for (const auto& transfer : submitted_) {
      transfer->done = true;
      transfer->result = fail(ErrorCode::kCancelled, url_ + ": source closed");
    }
    submitted_.clear();
  }

  Error cancelledOf(const Transfer& transfer) const {
    return {ErrorCode::kCancelled,
            fmt::format("{}: read of {} cancelled", url_, rangeText(transfer))};
  }

  static std::string rangeText(const Transfer& transfer) {
    if (transfer.kind == Transfer::Kind::kHeadAfterChange) return "HEAD";
    return fmt::format("bytes={}-{}", transfer.offset_bytes,
                       transfer.offset_bytes + transfer.length_bytes - 1);
  }

  CURL* takeEasy() {
    if (idle_easy_.empty()) return curl_easy_init();
    CURL* easy = idle_easy_.back();
    idle_easy_.pop_back();
    curl_easy_reset(easy);
    return easy;
  }

  void startAttempt(Transfer& transfer) {
    ++transfer.attempt;
    transfer.status = 0;
    transfer.status_text.clear();
    transfer.content_range.clear();
    transfer.etag.clear();
    transfer.last_modified.clear();
    transfer.retry_after.clear();
    transfer.body_started = false;
    transfer.last_activity = Clock::now();
    transfer.request_sent = false;
    transfer.received = 0;
    transfer.wire_bytes = 0;
    transfer.fault = Fault::kNone;
    transfer.fault_detail.clear();
    transfer.curl_error[0] = 0;
    transfer.source = this;
    CURL* easy = transfer.easy = takeEasy();
    curl_easy_setopt(easy, CURLOPT_URL, url_.c_str());
    curl_easy_setopt(easy, CURLOPT_PRIVATE, &transfer);
    curl_easy_setopt(easy, CURLOPT_ERRORBUFFER, transfer.curl_error);
    curl_easy_setopt(easy, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(easy, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(easy, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(easy, CURLOPT_FOLLOWLOCATION, 1L);
    curl_easy_setopt(easy, CURLOPT_MAXREDIRS, 5L);
    curl_easy_setopt(easy, CURLOPT_USERAGENT, options_.user_agent.c_str());
    curl_easy_setopt(easy, CURLOPT_TCP_KEEPALIVE, 1L);
    curl_easy_setopt(easy, CURLOPT_CONNECTTIMEOUT_MS, long(options_.connect_timeout.count()));
    curl_easy_setopt(easy, CURLOPT_TIMEOUT_MS, long(options_.request_timeout.count()));
    const bool https = lowercase(url_.substr(0, 8)) == "https://";
    curl_easy_setopt(easy, CURLOPT_HTTP_VERSION,
                     long(options_.http2_prior_knowledge ? CURL_HTTP_VERSION_2_PRIOR_KNOWLEDGE
                                                         : CURL_HTTP_VERSION_2TLS));
    // Where HTTP/2 is possible, a new request waits for the connection being set up rather
    // than opening another: it becomes a stream of that one.
    if (https || options_.http2_prior_knowledge) curl_easy_setopt(easy, CURLOPT_PIPEWAIT, 1L);
    if (!options_.verify_tls) {
      curl_easy_setopt(easy, CURLOPT_SSL_VERIFYPEER, 0L);
      curl_easy_setopt(easy, CURLOPT_SSL_VERIFYHOST, 0L);
    }
    curl_easy_setopt(easy, CURLOPT_HEADERFUNCTION, &HttpSource::onHeader);
    curl_easy_setopt(easy, CURLOPT_HEADERDATA, &transfer);
    curl_easy_setopt(easy, CURLOPT_WRITEFUNCTION, &HttpSource::onBody);
    curl_easy_setopt(easy, CURLOPT_WRITEDATA, &transfer);
    curl_easy_setopt(easy, CURLOPT_NOPROGRESS, 0L);
    curl_easy_setopt(easy, CURLOPT_XFERINFOFUNCTION, &HttpSource::onProgress);
    curl_easy_setopt(easy, CURLOPT_XFERINFODATA, &transfer);
    curl_slist_free_all(transfer.headers);
    transfer.headers = nullptr;
    if (transfer.kind == Transfer::Kind::kHeadAfterChange) {
      curl_easy_setopt(easy, CURLOPT_NOBODY, 1L);
    } else {
      const std::string range = fmt::format("{}-{}", transfer.offset_bytes,
                                            transfer.offset_bytes + transfer.length_bytes - 1);
      curl_easy_setopt(easy, CURLOPT_RANGE, range.c_str());
      // The version rule: a changed file answers 412 (If-Match), or, from a server that
      // ignores it, the whole new file (If-Range) whose transfer onBody stops at once.
      if (transfer.kind == Transfer::Kind::kRead) {
        if (!etag_.empty()) {
          transfer.headers = curl_slist_append(transfer.headers, ("If-Match: " + etag_).c_str());
          transfer.headers = curl_slist_append(transfer.headers, ("If-Range: " + etag_).c_str());
        } else if (!last_modified_.empty()) {
          transfer.headers = curl_slist_append(transfer.headers,
                                               ("If-Unmodified-Since: " + last_modified_).c_str());
          transfer.headers =
              curl_slist_append(transfer.headers, ("If-Range: " + last_modified_).c_str());
        }
      }
    }
    curl_easy_setopt(easy, CURLOPT_HTTPHEADER, transfer.headers);
    curl_multi_add_handle(multi_, easy);
    std::lock_guard lock(mutex_);
    ++stats_.requests;
    if (transfer.attempt > 1) ++stats_.retries;
  }

  /// Takes the handle out of the multi and back to the pool (the connection stays cached).
  void stopAttempt(Transfer& transfer) {
    if (!transfer.easy) return;
    curl_multi_remove_handle(multi_, transfer.easy);
    idle_easy_.push_back(transfer.easy);
    transfer.easy = nullptr;
    std::lock_guard lock(mutex_);
    stats_.bytes_received += transfer.wire_bytes;
    transfer.wire_bytes = 0;
  }

  /// After one attempt: completes the transfer, or returns true to retry it (not_before set).
  bool finishAttempt(Transfer& transfer, CURLcode code, std::mt19937_64& random) {
    curl_off_t total_us = 0, first_byte_us = 0;
    curl_easy_getinfo(transfer.easy, CURLINFO_TOTAL_TIME_T, &total_us);
    curl_easy_getinfo(transfer.easy, CURLINFO_STARTTRANSFER_TIME_T, &first_byte_us);
    stopAttempt(transfer);
    const std::string what = fmt::format("{}: {}", url_, rangeText(transfer));
    auto retryOrFail = [&](ErrorCode error_code, const std::string& cause,
                           std::chrono::milliseconds server_wait) -> bool {
      if (transfer.attempt < options_.max_attempts) {
        const uint32_t shift = std::min<uint32_t>(transfer.attempt - 1, 20);
        auto backoff = std::min<std::chrono::milliseconds>(options_.retry_initial * (1u << shift),
                                                           options_.retry_max);
        backoff = std::chrono::milliseconds(int64_t(
            double(backoff.count()) * std::uniform_real_distribution<double>(0.5, 1.0)(random)));
        if (server_wait.count() > 0) backoff = std::min(server_wait, options_.retry_after_max);
        transfer.not_before = Clock::now() + backoff;
        return true;
      }
      complete(transfer,
               fail(error_code,
                    fmt::format("{}: {} (after {} attempts)", what, cause, transfer.attempt)),
               true);
      return false;
    };

    if (transfer.kind == Transfer::Kind::kHeadAfterChange) {
      std::string now = !transfer.etag.empty()            ? transfer.etag
                        : !transfer.last_modified.empty() ? transfer.last_modified
                                                          : "unknown";
      Error error = transfer.change_error;
      error.message = fmt::format("{}, now {}); reopen it", error.message, now);
      setChanged(error);
      complete(transfer, Unexpected(error), true);
      return false;
    }
    if (transfer.fault == Fault::kCancelled) {
      complete(transfer, Unexpected(cancelledOf(transfer)), false);
      return false;
    }
    if (transfer.fault == Fault::kStalled)
      return retryOrFail(ErrorCode::kIo,
                         fmt::format("stalled: no byte for {} ms", options_.stall_timeout.count()),
                         {});
    if (transfer.fault == Fault::kChanged) {
      beginChangeReport(transfer, transfer.fault_detail);
      return true;
    }
    if (transfer.fault == Fault::kWholeFile) {
      if (transfer.kind == Transfer::Kind::kRead && !transfer.etag.empty() &&
          transfer.etag != etag_) {
        beginChangeReport(transfer, "");
        return true;
      }
      complete(transfer,
               fail(ErrorCode::kUnsupported,
                    fmt::format("{}: server does not honour byte ranges (answered 200 with the "
                                "whole file to a Range request)",
                                what)),
               true);
      return false;
    }
    if (transfer.fault == Fault::kBadRange || transfer.fault == Fault::kTooLong) {
      complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}", what, transfer.fault_detail)),
               true);
      return false;
    }
    if (code != CURLE_OK) {
      const std::string cause =
          transfer.curl_error[0] ? std::string(transfer.curl_error) : curl_easy_strerror(code);
      if (code == CURLE_PARTIAL_FILE)
        return retryOrFail(ErrorCode::kIo, "truncated response: " + cause, {});
      if (retryableCurlCode(code)) return retryOrFail(ErrorCode::kIo, cause, {});
      complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}", what, cause)), true);
      return false;
    }
    const long status = transfer.status;
    const std::string status_line = fmt::format(
        "HTTP {}{}{}", status, transfer.status_text.empty() ? "" : " ", transfer.status_text);
    if (status == 206) {
      if (!transfer.body_started) return retryOrFail(ErrorCode::kIo, "206 without a body", {});
      if (transfer.received != transfer.length_bytes)
        return retryOrFail(ErrorCode::kIo,
                           fmt::format("truncated response: {} of {} bytes", transfer.received,
                                       transfer.length_bytes),
                           {});
      if (transfer.kind == Transfer::Kind::kProbe) {
        transfer.length_bytes = transfer.received;
      }
      recordSample(transfer, double(total_us) / 1e6, double(first_byte_us) / 1e6);
      complete(transfer, {}, false);
      return false;
    }
    if (status == 412 && transfer.kind == Transfer::Kind::kRead) {
      beginChangeReport(transfer, "");
      return true;
    }
    if (status == 416) {
      ContentRange range;
      if (transfer.kind == Transfer::Kind::kProbe &&
          parseContentRange(transfer.content_range, range) && !range.has_range && range.has_total &&
          range.total == 0) {
        transfer.probe_total = 0;
        transfer.received = 0;
        complete(transfer, {}, false);
        return false;
      }
      if (transfer.kind == Transfer::Kind::kRead &&
          parseContentRange(transfer.content_range, range) && range.has_total &&
          range.total != size_bytes_) {
        beginChangeReport(transfer,
                          fmt::format("size was {} bytes, now {}", size_bytes_, range.total));
        return true;
      }
      complete(
          transfer,
          fail(ErrorCode::kIo, fmt::format("{}: {} (range not satisfiable)", what, status_line)),
          true);
      return false;
    }
    if (status == 404 || status == 410) {
      complete(transfer, fail(ErrorCode::kNotFound, fmt::format("{}: {}", what, status_line)),
               true);
      return false;
    }
    if (retryableStatus(status))
      return retryOrFail(
          ErrorCode::kIo, status_line,
          status == 429 || status == 503 ? retryAfter(transfer) : std::chrono::milliseconds(0));
    complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}", what, status_line)), true);
    return false;
  }

  std::chrono::milliseconds retryAfter(const Transfer& transfer) const {
    if (transfer.retry_after.empty()) return std::chrono::milliseconds(0);
    uint64_t seconds = 0;
    if (parseUint(transfer.retry_after, seconds))
      return std::chrono::milliseconds(std::min<uint64_t>(seconds, 86400) * 1000);
    const time_t when = curl_getdate(transfer.retry_after.c_str(), nullptr);
    if (when < 0) return std::chrono::milliseconds(0);
    const time_t now = ::time(nullptr);
    return std::chrono::milliseconds(when > now ? int64_t(when - now) * 1000 : 0);
  }

  /// The file changed: asks the server (HEAD) for its version now, for the message; the
  /// transfer completes with the error once that answer is in.
  void beginChangeReport(Transfer& transfer, const std::string& detail) {
    const std::string was =
        !etag_.empty() ? "ETag was " + etag_ : "Last-Modified was " + last_modified_;
    transfer.change_error = {
        ErrorCode::kCorrupt,
        fmt::format("{}: {}: archive changed on the server ({}{}", url_, rangeText(transfer),
                    detail.empty() ? "" : detail + "; ", was)};
    transfer.kind = Transfer::Kind::kHeadAfterChange;
    transfer.attempt = 0;
    transfer.not_before = Clock::now();
  }

  void setChanged(const Error& error) {
    std::lock_guard lock(mutex_);
    if (changed_.message.empty()) changed_ = error;
  }

  void recordSample(const Transfer& transfer, double seconds, double first_byte_seconds) {
    std::lock_guard lock(mutex_);
    recent_.push_back({Clock::now(), transfer.received, seconds, first_byte_seconds});
    if (recent_.size() > kRecentSamples) recent_.pop_front();
    if (transfer.prefetch) stats_.prefetched_bytes += transfer.received;
  }

  void complete(Transfer& transfer, Result<void> result, bool is_error) {
    curl_slist_free_all(transfer.headers);
    transfer.headers = nullptr;
    {
      std::lock_guard lock(mutex_);
      if (is_error) ++stats_.errors;
      if (!result && result.error().code == ErrorCode::kCancelled && transfer.cancel)
        ++stats_.cancelled;
      if (transfer.prefetch)
        transfer.prefetch->state =
            result ? PrefetchEntry::State::kReady : PrefetchEntry::State::kFailed;
      if (transfer.prefetch && !result) {
        auto it = std::find(prefetched_.begin(), prefetched_.end(), transfer.prefetch);
        if (it != prefetched_.end()) dropLocked(it);
      }
      transfer.result = std::move(result);
      transfer.done = true;
    }
    done_.notify_all();
  }

  /// At a 206's first body byte, its headers all in: is this the range asked, of the version
  /// opened? Sets the fault and returns false when not.
  bool acceptResponse(Transfer& transfer) const {
    ContentRange range;
    if (!parseContentRange(transfer.content_range, range) || !range.has_range) {
      transfer.fault = Fault::kBadRange;
      transfer.fault_detail =
          fmt::format("206 without a usable Content-Range (\"{}\")", transfer.content_range);
      return false;
    }
    if (transfer.kind == Transfer::Kind::kProbe) {
      if (!range.has_total || range.total == 0 || range.first != 0 ||
          range.last != std::min(kOpenBytes, range.total) - 1) {
        transfer.fault = Fault::kBadRange;
        transfer.fault_detail = fmt::format("server answered \"Content-Range: {}\" to bytes=0-{}",
                                            transfer.content_range, kOpenBytes - 1);
        return false;
      }
      transfer.probe_total = range.total;
      transfer.length_bytes = range.last + 1;
      return true;
    }
    if (range.has_total && range.total != size_bytes_) {
      transfer.fault = Fault::kChanged;
      transfer.fault_detail = fmt::format("size was {} bytes, now {}", size_bytes_, range.total);
      return false;
    }
    if ((!etag_.empty() && !transfer.etag.empty() && transfer.etag != etag_) ||
        (etag_.empty() && !last_modified_.empty() && !transfer.last_modified.empty() &&
         transfer.last_modified != last_modified_)) {
      transfer.fault = Fault::kChanged;
      return false;
    }
    if (range.first != transfer.offset_bytes ||
        range.last != transfer.offset_bytes + transfer.length_bytes - 1) {
      transfer.fault = Fault::kBadRange;
      transfer.fault_detail = fmt::format("server answered bytes {}-{}", range.first, range.last);
      return false;
    }
    return true;
  }

  // ---- libcurl callbacks (on the I/O thread) ----

  static size_t onHeader(char* data, size_t size, size_t count, void* user) {
    Transfer& transfer = *static_cast<Transfer*>(user);
    const size_t bytes = size * count;
    transfer.last_activity = Clock::now();
    transfer.request_sent = true;
    std::string_view line(data, bytes);
    if (line.rfind("HTTP/", 0) == 0) {
      // A new response (after a redirect or an interim 1xx): forget the previous one's.
      transfer.content_range.clear();
      transfer.etag.clear();
      transfer.last_modified.clear();
      transfer.retry_after.clear();
      const size_t space = line.find(' ');
      if (space != std::string_view::npos) {
        std::string rest = trim(line.substr(space + 1));
        transfer.status = std::strtol(rest.c_str(), nullptr, 10);
        const size_t text = rest.find(' ');
        transfer.status_text = text == std::string::npos ? "" : rest.substr(text + 1);
      }
      return bytes;
    }
    const size_t colon = line.find(':');
    if (colon == std::string_view::npos) return bytes;
    const std::string key = lowercase(trim(line.substr(0, colon)));
    std::string value = trim(line.substr(colon + 1));
    if (key == "content-range")
      transfer.content_range = std::move(value);
    else if (key == "etag")
      transfer.etag = std::move(value);
    else if (key == "last-modified")
      transfer.last_modified = std::move(value);
    else if (key == "retry-after")
      transfer.retry_after = std::move(value);
    return bytes;
  }

  static size_t onBody(char* data, size_t size, size_t count, void* user) {
    Transfer& transfer = *static_cast<Transfer*>(user);
    const size_t bytes = size * count;
    transfer.wire_bytes += bytes;
    transfer.last_activity = Clock::now();
    if (transfer.status == 200) {
      // Never download a whole archive by accident: stop at its first bytes.
      transfer.fault = Fault::kWholeFile;
      return CURL_WRITEFUNC_ERROR;
    }
    if (transfer.status != 206) return bytes;  // an error page: read and dropped
    if (!transfer.body_started) {
      transfer.body_started = true;
      if (!transfer.source->acceptResponse(transfer)) return CURL_WRITEFUNC_ERROR;
    }
    if (transfer.received + bytes > transfer.length_bytes) {
      transfer.fault = Fault::kTooLong;
      transfer.fault_detail =
          fmt::format("server sent more than the {} bytes asked", transfer.length_bytes);
      return CURL_WRITEFUNC_ERROR;
    }
    std::memcpy(transfer.out + transfer.received, data, bytes);
    transfer.received += bytes;
    return bytes;
  }

  static int onProgress(void* user, curl_off_t, curl_off_t, curl_off_t, curl_off_t) {
    Transfer& transfer = *static_cast<Transfer*>(user);
    if (transfer.cancel && transfer.cancel->load(std::memory_order_acquire)) {
      transfer.fault = Fault::kCancelled;
      return 1;
    }
    return 0;
  }

  const std::string url_;
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
  mutable LinkStats stats_;  ///< totals (recent kept apart)
  mutable std::deque<LinkSample> recent_;
};

}  // namespace

Result<std::shared_ptr<ByteSource>> openHttpSource(const std::string& url,
                                                   const HttpOptions& options) {
  if (!isRemoteUri(url))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: not an http:// or https:// URL", url));
  if (options.max_attempts == 0 || options.max_connections == 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: max_attempts and max_connections must be at least 1", url));
  // libcurl 7.88 (Debian 12) breaks every request on a reused prior-knowledge connection
  // (curl/curl#10634, fixed in 8.0): refuse the option rather than fail each read.
  if (options.http2_prior_knowledge && curl_version_info(CURLVERSION_NOW)->version_num < 0x080000)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: http2_prior_knowledge needs libcurl 8 or newer (this is {}); "
                            "HTTP/2 over https:// works",
                            url, curl_version_info(CURLVERSION_NOW)->version));
  auto source = std::make_shared<HttpSource>(url, options);
  TESSERA_TRY(source->probe());
  return std::shared_ptr<ByteSource>(std::move(source));
}

bool isRemoteUri(const std::string& path_or_url) {
  const std::string head = lowercase(path_or_url.substr(0, 8));
  return head.rfind("http://", 0) == 0 || head.rfind("https://", 0) == 0;
}

Result<std::shared_ptr<ByteSource>> openByteSource(const std::string& path_or_url) {
  if (isRemoteUri(path_or_url)) return openHttpSource(path_or_url);
  return openFileSource(path_or_url);
}

}  // namespace tessera
