// The HTTP byte source, the callers' side: ranged GETs handed to the I/O thread
// (http_io_thread.cpp), one multi handle per source, so the reads of many loader threads share
// keep-alive connections (and HTTP/2 streams) instead of each opening its own; fetch-ahead
// into a bounded buffer; waiting with cancellation. The class: http_source_impl.h.
#include <tessera/http_source.h>
#include <tessera/open.h>

#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include "reader/read_plan.h"
#include "http_source_impl.h"

namespace tessera {

namespace detail {

namespace {

void initCurlOnce() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

/// Strong comparison (RFC 9110, 8.8.3.2): weak tags never match.
bool strongEtag(const std::string& etag) {
  return !etag.empty() && etag.rfind("W/", 0) != 0;
}

}  // namespace

HttpSource::HttpSource(std::string url, HttpOptions options)
    : url_(std::move(url)), request_url_(url_), options_(std::move(options)) {
  initCurlOnce();
  multi_ = curl_multi_init();
  curl_multi_setopt(multi_, CURLMOPT_PIPELINING, long(CURLPIPE_MULTIPLEX));
  curl_multi_setopt(multi_, CURLMOPT_MAX_HOST_CONNECTIONS, long(options_.max_connections));
  curl_multi_setopt(multi_, CURLMOPT_MAX_TOTAL_CONNECTIONS, long(options_.max_connections));
  curl_multi_setopt(multi_, CURLMOPT_MAXCONNECTS, long(options_.max_connections));
  io_thread_ = std::thread([this] { ioLoop(); });
}

HttpSource::~HttpSource() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  curl_multi_wakeup(multi_);
  io_thread_.join();
  for (CURL* easy : idle_easy_) curl_easy_cleanup(easy);
  curl_multi_cleanup(multi_);
}

Result<void> HttpSource::probe() {
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

Result<void> HttpSource::read(uint64_t offset_bytes, std::span<uint8_t> out) const {
  return readRange(offset_bytes, out, nullptr);
}

Result<void> HttpSource::readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                                         const std::atomic<bool>& cancel) const {
  return readRange(offset_bytes, out, &cancel);
}

Result<void> HttpSource::readMany(std::span<const ByteRange> ranges) const {
  TESSERA_TRY(changedError());
  std::vector<detail::ReadRun> runs = detail::planReadRuns(ranges);
  std::vector<std::vector<uint8_t>> buffers(runs.size());
  std::vector<ByteRange> wanted;
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
    wanted.push_back({run.offset_bytes, run.length_bytes, out});
  }
  for (Result<void>& result : fetchRanges(wanted, nullptr))
    if (!result) return result;
  for (size_t i = 0; i < runs.size(); ++i)
    if (runs[i].members.size() > 1) detail::scatterRun(runs[i], ranges, buffers[i]);
  return {};
}

std::vector<Result<void>> HttpSource::readEach(std::span<const ByteRange> ranges,
                                               const std::atomic<bool>& cancel) const {
  std::vector<Result<void>> results(ranges.size());
  if (Result<void> changed = changedError(); !changed) {
    results.assign(ranges.size(), changed);
    return results;
  }
  // Ascending for the Range header; `order` maps them back to their results.
  std::vector<size_t> order;
  for (size_t i = 0; i < ranges.size(); ++i) {
    const ByteRange& range = ranges[i];
    if (Result<void> bounds = checkBounds(range.offset_bytes, range.length_bytes); !bounds) {
      results[i] = std::move(bounds);
      continue;
    }
    if (range.length_bytes == 0) continue;
    Result<bool> taken =
        takeBuffered(range.offset_bytes, {range.out, size_t(range.length_bytes)}, &cancel);
    if (!taken)
      results[i] = forwardError(taken);
    else if (!*taken)
      order.push_back(i);
  }
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return ranges[a].offset_bytes < ranges[b].offset_bytes; });
  std::vector<ByteRange> wanted;
  for (size_t i : order) wanted.push_back(ranges[i]);
  std::vector<Result<void>> fetched = fetchRanges(wanted, &cancel);
  for (size_t k = 0; k < order.size(); ++k) results[order[k]] = std::move(fetched[k]);
  return results;
}

std::vector<Result<void>> HttpSource::fetchRanges(std::span<const ByteRange> wanted,
                                                  const std::atomic<bool>* cancel) const {
  const size_t per_request =
      multi_range_refused_.load() ? 1 : std::max<size_t>(1, options_.max_ranges_per_request);
  std::vector<std::shared_ptr<Transfer>> transfers;
  std::vector<size_t> first_of;  ///< per transfer: the index of its first range in `wanted`
  for (size_t i = 0; i < wanted.size();) {
    // The body of a multi-range request is buffered before it is split: bound it.
    size_t count = 1;
    uint64_t bytes = wanted[i].length_bytes;
    while (count < per_request && i + count < wanted.size() &&
           bytes + wanted[i + count].length_bytes <= kMultiRangeMaxBytes)
      bytes += wanted[i + count++].length_bytes;
    const std::span<const ByteRange> group = wanted.subspan(i, count);
    first_of.push_back(i);
    i += count;
    auto transfer = std::make_shared<Transfer>();
    transfer->offset_bytes = group.front().offset_bytes;
    transfer->length_bytes =
        group.back().offset_bytes + group.back().length_bytes - transfer->offset_bytes;
    transfer->out = group.front().out;
    transfer->cancel = cancel;
    if (group.size() > 1) {
      transfer->parts.assign(group.begin(), group.end());
      transfer->body_cap = group.size() * kMultipartPartOverheadBytes + 1024;
      for (const ByteRange& part : group) transfer->body_cap += part.length_bytes;
    }
    transfers.push_back(std::move(transfer));
  }
  submit(transfers);
  std::vector<Result<void>> results(wanted.size());
  std::vector<size_t> again;  ///< ranges of refused multi-range requests
  for (size_t t = 0; t < transfers.size(); ++t) {
    const Transfer& transfer = *transfers[t];
    Result<void> one = wait(transfer);
    const size_t count = std::max<size_t>(1, transfer.parts.size());
    for (size_t k = 0; k < count; ++k) {
      const size_t index = first_of[t] + k;
      if (!one && transfer.multi_refused)
        again.push_back(index);
      else if (!one)
        results[index] = one;
      else if (k < transfer.part_errors.size() && !transfer.part_errors[k].empty())
        results[index] = fail(
            ErrorCode::kIo, fmt::format("{}: bytes={}-{} of a multi-range request: {}", url_,
                                        wanted[index].offset_bytes,
                                        wanted[index].offset_bytes + wanted[index].length_bytes - 1,
                                        transfer.part_errors[k]));
    }
  }
  if (again.empty()) return results;
  // multi_range_refused_ is set by now: these go one range a request.
  std::vector<ByteRange> retry;
  for (size_t index : again) retry.push_back(wanted[index]);
  std::vector<Result<void>> retried = fetchRanges(retry, cancel);
  for (size_t k = 0; k < again.size(); ++k) results[again[k]] = std::move(retried[k]);
  return results;
}

uint64_t HttpSource::prefetch(std::span<const ByteRange> ranges) const {
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

std::optional<LinkStats> HttpSource::linkStats() const {
  std::lock_guard lock(mutex_);
  LinkStats stats = stats_;
  stats.recent.assign(recent_.begin(), recent_.end());
  return stats;
}

Result<void> HttpSource::checkBounds(uint64_t offset_bytes, uint64_t length_bytes) const {
  if (offset_bytes > size_bytes_ || length_bytes > size_bytes_ - offset_bytes)
    return fail(ErrorCode::kIo, fmt::format("{}: read [{}, +{}) past the end ({} bytes)", url_,
                                            offset_bytes, length_bytes, size_bytes_));
  return {};
}

Result<void> HttpSource::readRange(uint64_t offset_bytes, std::span<uint8_t> out,
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

Unexpected HttpSource::cancelledError(uint64_t offset_bytes, std::span<uint8_t> out) const {
  {
    std::lock_guard lock(mutex_);
    ++stats_.cancelled;
  }
  return fail(ErrorCode::kCancelled, fmt::format("{}: read of bytes={}-{} cancelled", url_,
                                                 offset_bytes, offset_bytes + out.size() - 1));
}

Result<void> HttpSource::changedError() const {
  std::lock_guard lock(mutex_);
  if (changed_.message.empty()) return {};
  return Unexpected(changed_);
}

Result<bool> HttpSource::takeBuffered(uint64_t offset_bytes, std::span<uint8_t> out,
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

bool HttpSource::coveredLocked(uint64_t offset_bytes, uint64_t length_bytes) const {
  if (offset_bytes + length_bytes <= head_.size()) return true;
  return std::any_of(prefetched_.begin(), prefetched_.end(), [&](const auto& e) {
    return e->state != PrefetchEntry::State::kFailed && e->offset_bytes <= offset_bytes &&
           offset_bytes + length_bytes <= e->offset_bytes + e->bytes.size();
  });
}

void HttpSource::dropLocked(std::list<std::shared_ptr<PrefetchEntry>>::iterator it) const {
  prefetch_bytes_ -= (*it)->bytes.size();
  prefetched_.erase(it);
}

void HttpSource::submit(const std::vector<std::shared_ptr<Transfer>>& transfers) const {
  if (transfers.empty()) return;
  {
    std::lock_guard lock(mutex_);
    for (const auto& transfer : transfers) submitted_.push_back(transfer);
  }
  curl_multi_wakeup(multi_);
}

Result<void> HttpSource::wait(const Transfer& transfer) const {
  std::unique_lock lock(mutex_);
  done_.wait(lock, [&] { return transfer.done; });
  return transfer.result;
}

Result<void> HttpSource::run(const std::shared_ptr<Transfer>& transfer) const {
  submit({transfer});
  return wait(*transfer);
}

}  // namespace detail

Result<std::shared_ptr<ByteSource>> openHttpSource(const std::string& url,
                                                   const HttpOptions& options) {
  if (!isRemoteUri(url) || url.rfind("s3://", 0) == 0)
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
  auto source = std::make_shared<detail::HttpSource>(url, options);
  TESSERA_TRY(source->probe());
  return std::shared_ptr<ByteSource>(std::move(source));
}

}  // namespace tessera
