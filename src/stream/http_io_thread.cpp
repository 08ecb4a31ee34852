// The HTTP byte source's I/O thread (http_source_impl.h): it alone drives libcurl's multi
// handle, starts, retries and stalls out attempts, checks every response against the range
// asked and the version opened, and completes the callers' transfers.
#include <algorithm>
#include <charconv>
#include <cstring>
#include <random>
#include <system_error>

#include <fmt/format.h>

#include "content_range.h"
#include "multipart_ranges.h"
#include "http_source_impl.h"

namespace tessera::detail {

namespace {

std::string trim(std::string_view text) {
  size_t begin = 0, end = text.size();
  while (begin < end && std::isspace(static_cast<unsigned char>(text[begin]))) ++begin;
  while (end > begin && std::isspace(static_cast<unsigned char>(text[end - 1]))) --end;
  return std::string(text.substr(begin, end - begin));
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

}  // namespace

void HttpSource::ioLoop() {
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
      stats_.max_in_flight = std::max(stats_.max_in_flight, stats_.in_flight);
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

Error HttpSource::cancelledOf(const Transfer& transfer) const {
  return {ErrorCode::kCancelled,
          fmt::format("{}: read of {} cancelled", url_, rangeText(transfer))};
}

std::string HttpSource::rangeText(const Transfer& transfer) {
  if (transfer.kind == Transfer::Kind::kHeadAfterChange) return "HEAD";
  if (!transfer.parts.empty()) {
    // The first few ranges name the request well enough; the count says the rest.
    std::string text = "bytes=";
    for (size_t i = 0; i < std::min<size_t>(transfer.parts.size(), 3); ++i)
      text += fmt::format("{}{}-{}", i ? "," : "", transfer.parts[i].offset_bytes,
                          transfer.parts[i].offset_bytes + transfer.parts[i].length_bytes - 1);
    if (transfer.parts.size() > 3) text += fmt::format(",... ({} ranges)", transfer.parts.size());
    return text;
  }
  return fmt::format("bytes={}-{}", transfer.offset_bytes,
                     transfer.offset_bytes + transfer.length_bytes - 1);
}

CURL* HttpSource::takeEasy() {
  if (idle_easy_.empty()) return curl_easy_init();
  CURL* easy = idle_easy_.back();
  idle_easy_.pop_back();
  curl_easy_reset(easy);
  return easy;
}

void HttpSource::startAttempt(Transfer& transfer) {
  ++transfer.attempt;
  transfer.status = 0;
  transfer.status_text.clear();
  transfer.content_range.clear();
  transfer.content_type.clear();
  transfer.etag.clear();
  transfer.last_modified.clear();
  transfer.retry_after.clear();
  transfer.body.clear();
  transfer.boundary.clear();
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
  curl_easy_setopt(easy, CURLOPT_URL, request_url_.c_str());
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
  const long version = options_.http2_prior_knowledge ? CURL_HTTP_VERSION_2_PRIOR_KNOWLEDGE
                       : options_.http2               ? CURL_HTTP_VERSION_2TLS
                                                      : CURL_HTTP_VERSION_1_1;
  curl_easy_setopt(easy, CURLOPT_HTTP_VERSION, version);
  // Where HTTP/2 is possible, a new request waits for the connection being set up rather
  // than opening another: it becomes a stream of that one.
  if ((https && options_.http2) || options_.http2_prior_knowledge)
    curl_easy_setopt(easy, CURLOPT_PIPEWAIT, 1L);
  if (!options_.verify_tls) {
    curl_easy_setopt(easy, CURLOPT_SSL_VERIFYPEER, 0L);
    curl_easy_setopt(easy, CURLOPT_SSL_VERIFYHOST, 0L);
  } else if (!options_.ca_file.empty()) {
    curl_easy_setopt(easy, CURLOPT_CAINFO, options_.ca_file.c_str());
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
  if (!options_.bearer_token.empty())
    transfer.headers = curl_slist_append(
        transfer.headers, ("Authorization: Bearer " + options_.bearer_token).c_str());
  if (!options_.aws.access_key_id.empty()) signForAws(easy, transfer);
  if (transfer.kind == Transfer::Kind::kHeadAfterChange) {
    curl_easy_setopt(easy, CURLOPT_NOBODY, 1L);
  } else {
    // One range, or the parts of a multi-range request: "a-b" or "a-b,c-d,...".
    std::string range;
    if (transfer.parts.empty())
      range = fmt::format("{}-{}", transfer.offset_bytes,
                          transfer.offset_bytes + transfer.length_bytes - 1);
    for (const ByteRange& part : transfer.parts)
      range += fmt::format("{}{}-{}", range.empty() ? "" : ",", part.offset_bytes,
                           part.offset_bytes + part.length_bytes - 1);
    curl_easy_setopt(easy, CURLOPT_RANGE, range.c_str());
    // The version rule: a changed file answers 412 (If-Match), or, from a server that
    // ignores it, the whole new file (If-Range) whose transfer onBody stops at once.
    if (transfer.kind == Transfer::Kind::kRead) {
      if (!etag_.empty()) {
        transfer.headers = curl_slist_append(transfer.headers, ("If-Match: " + etag_).c_str());
        transfer.headers = curl_slist_append(transfer.headers, ("If-Range: " + etag_).c_str());
      } else if (!last_modified_.empty()) {
        transfer.headers =
            curl_slist_append(transfer.headers, ("If-Unmodified-Since: " + last_modified_).c_str());
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

void HttpSource::signForAws(CURL* easy, Transfer& transfer) {
  // libcurl computes the signature (CURLOPT_AWS_SIGV4); S3 also wants the payload's hash as a
  // header, which libcurl then signs as it is: every request here is a GET or HEAD without a
  // body, whose hash is that of the empty string.
  const HttpOptions::AwsSigning& aws = options_.aws;
  // libcurl copies string options: the temporary may go.
  curl_easy_setopt(easy, CURLOPT_AWS_SIGV4,
                   fmt::format("aws:amz:{}:{}", aws.region, aws.service).c_str());
  curl_easy_setopt(easy, CURLOPT_USERNAME, aws.access_key_id.c_str());
  curl_easy_setopt(easy, CURLOPT_PASSWORD, aws.secret_access_key.c_str());
  transfer.headers = curl_slist_append(
      transfer.headers,
      "x-amz-content-sha256: e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  if (!aws.session_token.empty())
    transfer.headers =
        curl_slist_append(transfer.headers, ("x-amz-security-token: " + aws.session_token).c_str());
}

void HttpSource::stopAttempt(Transfer& transfer) {
  if (!transfer.easy) return;
  // A transfer that opened a connection tells which protocol that connection settled on.
  long connects = 0, version = CURL_HTTP_VERSION_NONE;
  curl_easy_getinfo(transfer.easy, CURLINFO_NUM_CONNECTS, &connects);
  curl_easy_getinfo(transfer.easy, CURLINFO_HTTP_VERSION, &version);
  curl_multi_remove_handle(multi_, transfer.easy);
  idle_easy_.push_back(transfer.easy);
  transfer.easy = nullptr;
  std::lock_guard lock(mutex_);
  stats_.bytes_received += transfer.wire_bytes;
  transfer.wire_bytes = 0;
  if (connects > 0) {
    stats_.connections += uint64_t(connects);
    if (version == CURL_HTTP_VERSION_2_0)
      stats_.http2_connections += uint64_t(connects);
    else if (version == CURL_HTTP_VERSION_1_0 || version == CURL_HTTP_VERSION_1_1)
      stats_.http1_connections += uint64_t(connects);
  }
}

bool HttpSource::finishAttempt(Transfer& transfer, CURLcode code, std::mt19937_64& random) {
  curl_off_t total_us = 0, first_byte_us = 0;
  curl_easy_getinfo(transfer.easy, CURLINFO_TOTAL_TIME_T, &total_us);
  curl_easy_getinfo(transfer.easy, CURLINFO_STARTTRANSFER_TIME_T, &first_byte_us);
  stopAttempt(transfer);
  const std::string what = fmt::format("{}: {}", url_, rangeText(transfer));
  if (transfer.kind == Transfer::Kind::kHeadAfterChange) {
    finishChangeReport(transfer);
    return false;
  }
  if (transfer.fault != Fault::kNone) return finishFault(transfer, what, random);
  if (code != CURLE_OK) return finishCurlError(transfer, code, what, random);
  return finishResponse(transfer, what, double(total_us) / 1e6, double(first_byte_us) / 1e6,
                        random);
}

bool HttpSource::retryOrFail(Transfer& transfer, ErrorCode code, const std::string& what,
                             const std::string& cause, std::chrono::milliseconds server_wait,
                             std::mt19937_64& random) {
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
           fail(code, fmt::format("{}: {} (after {} attempts)", what, cause, transfer.attempt)),
           true);
  return false;
}

void HttpSource::finishChangeReport(Transfer& transfer) {
  std::string now = !transfer.etag.empty()            ? transfer.etag
                    : !transfer.last_modified.empty() ? transfer.last_modified
                                                      : "unknown";
  Error error = transfer.change_error;
  error.message = fmt::format("{}, now {}); reopen it", error.message, now);
  setChanged(error);
  complete(transfer, Unexpected(error), true);
}

bool HttpSource::finishFault(Transfer& transfer, const std::string& what, std::mt19937_64& random) {
  switch (transfer.fault) {
    case Fault::kNone: break;
    case Fault::kCancelled:
      complete(transfer, Unexpected(cancelledOf(transfer)), false);
      return false;
    case Fault::kStalled:
      return retryOrFail(transfer, ErrorCode::kIo, what,
                         fmt::format("stalled: no byte for {} ms", options_.stall_timeout.count()),
                         {}, random);
    case Fault::kChanged: beginChangeReport(transfer, transfer.fault_detail); return true;
    case Fault::kWholeFile:
      if (transfer.kind == Transfer::Kind::kRead && !transfer.etag.empty() &&
          transfer.etag != etag_) {
        beginChangeReport(transfer, "");
        return true;
      }
      if (transfer.parts.empty()) {
        complete(transfer,
                 fail(ErrorCode::kUnsupported,
                      fmt::format("{}: server does not honour byte ranges (answered 200 with the "
                                  "whole file to a Range request)",
                                  what)),
                 true);
        return false;
      }
      transfer.fault_detail = "answered 200 with the whole file";
      [[fallthrough]];
    case Fault::kMultiRangeRefused:
      // Not an error of the read: its ranges are fetched again one by one (fetchRanges).
      multi_range_refused_.store(true);
      transfer.multi_refused = true;
      complete(transfer,
               fail(ErrorCode::kUnsupported,
                    fmt::format("{}: server does not do multi-range requests ({})", what,
                                transfer.fault_detail)),
               false);
      return false;
    case Fault::kBadRange:
    case Fault::kTooLong:
      complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}", what, transfer.fault_detail)),
               true);
      return false;
  }
  TESSERA_CHECK(false) << what << ": finishFault without a fault";
  return false;
}

bool HttpSource::finishCurlError(Transfer& transfer, CURLcode code, const std::string& what,
                                 std::mt19937_64& random) {
  const std::string cause =
      transfer.curl_error[0] ? std::string(transfer.curl_error) : curl_easy_strerror(code);
  if (code == CURLE_PARTIAL_FILE)
    return retryOrFail(transfer, ErrorCode::kIo, what, "truncated response: " + cause, {}, random);
  if (retryableCurlCode(code))
    return retryOrFail(transfer, ErrorCode::kIo, what, cause, {}, random);
  complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}", what, cause)), true);
  return false;
}

bool HttpSource::finishResponse(Transfer& transfer, const std::string& what, double seconds,
                                double first_byte_seconds, std::mt19937_64& random) {
  const long status = transfer.status;
  const std::string status_line = fmt::format(
      "HTTP {}{}{}", status, transfer.status_text.empty() ? "" : " ", transfer.status_text);
  if (status == 206) {
    if (!transfer.body_started)
      return retryOrFail(transfer, ErrorCode::kIo, what, "206 without a body", {}, random);
    if (!transfer.parts.empty()) {
      if (std::string why = scatterMultiBody(transfer); !why.empty()) {
        complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}", what, why)), true);
        return false;
      }
      transfer.received = transfer.body.size();
      recordSample(transfer, seconds, first_byte_seconds);
      transfer.body = {};
      const auto failed =
          size_t(std::count_if(transfer.part_errors.begin(), transfer.part_errors.end(),
                               [](const std::string& e) { return !e.empty(); }));
      if (failed) {
        std::lock_guard lock(mutex_);
        stats_.errors += failed;
      }
      complete(transfer, {}, false);
      return false;
    }
    if (transfer.received != transfer.length_bytes)
      return retryOrFail(transfer, ErrorCode::kIo, what,
                         fmt::format("truncated response: {} of {} bytes", transfer.received,
                                     transfer.length_bytes),
                         {}, random);
    if (transfer.kind == Transfer::Kind::kProbe) {
      transfer.length_bytes = transfer.received;
    }
    recordSample(transfer, seconds, first_byte_seconds);
    complete(transfer, {}, false);
    return false;
  }
  if (status == 412 && transfer.kind == Transfer::Kind::kRead) {
    beginChangeReport(transfer, "");
    return true;
  }
  if (status == 416) return finishUnsatisfiable(transfer, what, status_line);
  if (status == 401 || status == 403) return finishRefused(transfer, what, status_line);
  if (status == 404 || status == 410) {
    complete(transfer, fail(ErrorCode::kNotFound, fmt::format("{}: {}", what, status_line)), true);
    return false;
  }
  if (retryableStatus(status))
    return retryOrFail(
        transfer, ErrorCode::kIo, what, status_line,
        status == 429 || status == 503 ? retryAfter(transfer) : std::chrono::milliseconds(0),
        random);
  complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}", what, status_line)), true);
  return false;
}

bool HttpSource::finishRefused(Transfer& transfer, const std::string& what,
                               const std::string& status_line) {
  if (options_.renew_url && !transfer.renewed) {
    const std::string renewed = options_.renew_url(request_url_);
    if (!renewed.empty() && renewed != request_url_) {
      request_url_ = renewed;
      transfer.renewed = true;
      transfer.not_before = Clock::now();
      return true;
    }
  }
  std::string hint = transfer.status == 401
                         ? "the server wants a bearer token (HttpOptions::bearer_token, "
                           "TESSERA_TOKEN for the tools) or a signed URL"
                         : "the token or signed URL does not grant this request, or expired";
  if (!options_.aws.access_key_id.empty())
    hint = fmt::format(
        "the object store refused the request signed with access key id {} "
        "(region {}): wrong secret, expired session token, or no read access",
        options_.aws.access_key_id, options_.aws.region);
  complete(transfer, fail(ErrorCode::kIo, fmt::format("{}: {}: {}", what, status_line, hint)),
           true);
  return false;
}

bool HttpSource::finishUnsatisfiable(Transfer& transfer, const std::string& what,
                                     const std::string& status_line) {
  ContentRange range;
  if (transfer.kind == Transfer::Kind::kProbe && parseContentRange(transfer.content_range, range) &&
      !range.has_range && range.has_total && range.total == 0) {
    transfer.probe_total = 0;
    transfer.received = 0;
    complete(transfer, {}, false);
    return false;
  }
  if (transfer.kind == Transfer::Kind::kRead && parseContentRange(transfer.content_range, range) &&
      range.has_total && range.total != size_bytes_) {
    beginChangeReport(transfer, fmt::format("size was {} bytes, now {}", size_bytes_, range.total));
    return true;
  }
  complete(transfer,
           fail(ErrorCode::kIo, fmt::format("{}: {} (range not satisfiable)", what, status_line)),
           true);
  return false;
}

std::chrono::milliseconds HttpSource::retryAfter(const Transfer& transfer) const {
  if (transfer.retry_after.empty()) return std::chrono::milliseconds(0);
  uint64_t seconds = 0;
  if (parseHttpUint(transfer.retry_after, seconds))
    return std::chrono::milliseconds(std::min<uint64_t>(seconds, 86400) * 1000);
  const time_t when = curl_getdate(transfer.retry_after.c_str(), nullptr);
  if (when < 0) return std::chrono::milliseconds(0);
  const time_t now = ::time(nullptr);
  return std::chrono::milliseconds(when > now ? int64_t(when - now) * 1000 : 0);
}

void HttpSource::beginChangeReport(Transfer& transfer, const std::string& detail) {
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

void HttpSource::setChanged(const Error& error) {
  std::lock_guard lock(mutex_);
  if (changed_.message.empty()) changed_ = error;
}

void HttpSource::recordSample(const Transfer& transfer, double seconds, double first_byte_seconds) {
  std::lock_guard lock(mutex_);
  recent_.push_back({Clock::now(), transfer.received, seconds, first_byte_seconds});
  if (recent_.size() > kRecentSamples) recent_.pop_front();
  if (transfer.prefetch) stats_.prefetched_bytes += transfer.received;
}

void HttpSource::complete(Transfer& transfer, Result<void> result, bool is_error) {
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

bool HttpSource::acceptResponse(Transfer& transfer) const {
  ContentRange range;
  const bool multipart =
      !transfer.parts.empty() && multipartBoundary(transfer.content_type, transfer.boundary);
  if (!multipart && (!parseContentRange(transfer.content_range, range) || !range.has_range)) {
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
  if (!transfer.parts.empty()) return multipart || acceptMultiResponse(transfer, range);
  if (range.first != transfer.offset_bytes ||
      range.last != transfer.offset_bytes + transfer.length_bytes - 1) {
    transfer.fault = Fault::kBadRange;
    transfer.fault_detail = fmt::format("server answered bytes {}-{}", range.first, range.last);
    return false;
  }
  return true;
}

bool HttpSource::acceptMultiResponse(Transfer& transfer, const ContentRange& range) const {
  // RFC 9110 lets a server answer several ranges with one that holds them all; within the
  // body cap that is as good as the parts.
  const ByteRange& last = transfer.parts.back();
  if (range.first <= transfer.parts.front().offset_bytes &&
      range.last >= last.offset_bytes + last.length_bytes - 1 &&
      range.last - range.first < transfer.body_cap) {
    transfer.single = range;
    return true;
  }
  transfer.fault = Fault::kMultiRangeRefused;
  transfer.fault_detail = fmt::format("answered bytes {}-{} only", range.first, range.last);
  return false;
}

size_t HttpSource::bufferMultiBody(Transfer& transfer, const char* data, size_t bytes) {
  if (transfer.body.size() + bytes > transfer.body_cap) {
    transfer.fault = Fault::kTooLong;
    transfer.fault_detail = fmt::format("server sent more than the {} bytes {} ranges need",
                                        transfer.body_cap, transfer.parts.size());
    return CURL_WRITEFUNC_ERROR;
  }
  transfer.body.insert(transfer.body.end(), data, data + bytes);
  transfer.received = transfer.body.size();
  return bytes;
}

std::string HttpSource::scatterMultiBody(Transfer& transfer) const {
  std::vector<MultipartPart> parts;
  std::string malformed;
  if (transfer.boundary.empty()) {
    const uint64_t length = transfer.single.last - transfer.single.first + 1;
    if (transfer.body.size() != length)
      return fmt::format("truncated response: {} of {} bytes", transfer.body.size(), length);
    parts.push_back({transfer.single, 0});
  } else if (std::string why = parseMultipartByteranges(transfer.body, transfer.boundary, parts);
             !why.empty()) {
    // The parts before the fault are whole and delimited: their ranges are still good.
    malformed = "malformed multipart/byteranges answer: " + why;
  }
  // Another size means another version of the file: no part of it may be used.
  for (const MultipartPart& part : parts)
    if (part.range.has_total && part.range.total != size_bytes_)
      return fmt::format("a part of the answer gives the size {} bytes, not {}", part.range.total,
                         size_bytes_);
  // Every range asked must lie inside one part: never a neighbour's bytes, never a gap. A
  // range without one fails alone; the others are delivered.
  transfer.part_errors.assign(transfer.parts.size(), std::string());
  for (size_t i = 0; i < transfer.parts.size(); ++i) {
    const ByteRange& wanted = transfer.parts[i];
    const uint64_t wanted_last = wanted.offset_bytes + wanted.length_bytes - 1;
    auto it = std::find_if(parts.begin(), parts.end(), [&](const MultipartPart& part) {
      return part.range.first <= wanted.offset_bytes && wanted_last <= part.range.last;
    });
    if (it == parts.end()) {
      transfer.part_errors[i] = !malformed.empty()
                                    ? malformed
                                    : fmt::format("the answer has no part holding bytes {}-{}",
                                                  wanted.offset_bytes, wanted_last);
      continue;
    }
    std::memcpy(wanted.out,
                transfer.body.data() + it->data_offset + (wanted.offset_bytes - it->range.first),
                wanted.length_bytes);
  }
  return "";
}

size_t HttpSource::onHeader(char* data, size_t size, size_t count, void* user) {
  Transfer& transfer = *static_cast<Transfer*>(user);
  const size_t bytes = size * count;
  transfer.last_activity = Clock::now();
  transfer.request_sent = true;
  std::string_view line(data, bytes);
  if (line.rfind("HTTP/", 0) == 0) {
    // A new response (after a redirect or an interim 1xx): forget the previous one's.
    transfer.content_range.clear();
    transfer.content_type.clear();
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
  else if (key == "content-type")
    transfer.content_type = std::move(value);
  else if (key == "etag")
    transfer.etag = std::move(value);
  else if (key == "last-modified")
    transfer.last_modified = std::move(value);
  else if (key == "retry-after")
    transfer.retry_after = std::move(value);
  return bytes;
}

size_t HttpSource::onBody(char* data, size_t size, size_t count, void* user) {
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
  if (!transfer.parts.empty()) return bufferMultiBody(transfer, data, bytes);
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

int HttpSource::onProgress(void* user, curl_off_t, curl_off_t, curl_off_t, curl_off_t) {
  Transfer& transfer = *static_cast<Transfer*>(user);
  if (transfer.cancel && transfer.cancel->load(std::memory_order_acquire)) {
    transfer.fault = Fault::kCancelled;
    return 1;
  }
  return 0;
}

}  // namespace tessera::detail
