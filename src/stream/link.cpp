// The link estimator and the simulated link (Marvie & Bouatouch, part III: adapting to the
// measured bandwidth, with bandwidth simulation for their measurements).
#include <tessera/link.h>

#include <algorithm>
#include <cctype>
#include <cmath>

#include <fmt/format.h>

namespace tessera {

double LinkEstimate::bytesWithin(double seconds) const {
  return bytes_per_s * std::max(0.0, seconds - latency_s);
}

LinkEstimator::LinkEstimator(const Options& options) : options_(options) {
  options_.window_s = std::max(1e-3, options_.window_s);
  options_.latency_reads = std::max(1u, options_.latency_reads);
}

void LinkEstimator::accountBusyLocked(Clock::time_point at) {
  // Reads report from several threads: an event stamped before the last one counts as at it.
  if (at < last_event_) at = last_event_;
  if (in_flight_ > 0) pending_busy_s_ += std::chrono::duration<double>(at - last_event_).count();
  last_event_ = at;
}

void LinkEstimator::readStarted(Clock::time_point at) {
  std::lock_guard lock(mutex_);
  accountBusyLocked(at);
  ++in_flight_;
}

void LinkEstimator::readFinished(Clock::time_point started, Clock::time_point finished,
                                 uint64_t bytes) {
  std::lock_guard lock(mutex_);
  accountBusyLocked(finished);
  if (in_flight_ > 0) --in_flight_;
  if (bytes == 0) return;
  // Aggregate rate: bytes over the wall time during which anything was in flight, so reads in
  // parallel add up instead of each being charged its whole duration.
  const double busy = pending_busy_s_;
  pending_busy_s_ = 0;
  const double weight = std::exp(-busy / options_.window_s);
  weighted_bytes_ = weighted_bytes_ * weight + double(bytes);
  weighted_busy_s_ = weighted_busy_s_ * weight + busy;
  recent_.emplace_back(std::chrono::duration<double>(finished - started).count(), double(bytes));
  while (recent_.size() > options_.latency_reads) recent_.pop_front();
  ++reads_;
  bytes_ += bytes;
}

void LinkEstimator::queueWait(Clock::duration waited) {
  const double s = std::max(0.0, std::chrono::duration<double>(waited).count());
  std::lock_guard lock(mutex_);
  queue_wait_s_ =
      queue_wait_s_ < 0 ? s : queue_wait_s_ + options_.queue_wait_weight * (s - queue_wait_s_);
}

LinkEstimate LinkEstimator::estimate() const {
  std::lock_guard lock(mutex_);
  LinkEstimate e;
  e.reads = reads_;
  e.bytes = bytes_;
  e.queue_wait_s = std::max(0.0, queue_wait_s_);
  if (reads_ == 0) return e;
  // Reads that took no measurable time (memory, page cache) bound the rate only from below.
  e.bytes_per_s = weighted_bytes_ / std::max(weighted_busy_s_, 1e-9);
  double latency = 1e300;
  for (const auto& sample : recent_) latency = std::min(latency, sample.first);
  e.latency_s = latency;
  return e;
}

Result<LinkModel> parseLinkModel(const std::string& text) {
  auto bad = [&](const std::string& why) -> Result<LinkModel> {
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("link '{}': {} (expected RATE:RTT, e.g. 20mbit:40ms)", text, why));
  };
  const size_t colon = text.find(':');
  if (colon == std::string::npos) return bad("no ':' between rate and round trip");
  // A number followed by a unit from `units` (lower case); the unit is required.
  auto parse = [](std::string part, std::initializer_list<std::pair<const char*, double>> units,
                  double& value) {
    for (char& c : part) c = char(std::tolower(static_cast<unsigned char>(c)));
    size_t used = 0;
    double number = 0;
    try {
      number = std::stod(part, &used);
    } catch (...) {
      return false;
    }
    const std::string unit = part.substr(used);
    for (const auto& [name, scale] : units)
      if (unit == name) {
        value = number * scale;
        return std::isfinite(value);
      }
    return false;
  };
  LinkModel model;
  if (!parse(text.substr(0, colon),
             {{"bit", 1}, {"kbit", 1e3}, {"mbit", 1e6}, {"gbit", 1e9}, {"bps", 1}},
             model.bits_per_s))
    return bad("rate must be a number with bit, kbit, mbit or gbit");
  if (!parse(text.substr(colon + 1), {{"us", 1e-6}, {"ms", 1e-3}, {"s", 1}}, model.rtt_s))
    return bad("round trip must be a number with us, ms or s");
  if (!(model.bits_per_s >= 1000 && model.bits_per_s <= 1e12))
    return bad("rate must be between 1kbit and 1000gbit");
  if (!(model.rtt_s >= 0 && model.rtt_s <= 10)) return bad("round trip must be between 0 and 10 s");
  return model;
}

namespace {

/// How often a waiting read looks at its cancel flag.
constexpr auto kCancelCheck = std::chrono::milliseconds(5);
/// Link time of one slice: reads in flight take turns at this granularity.
constexpr double kSliceS = 0.005;
/// Reads kept for linkStats().recent, as the HTTP source keeps.
constexpr size_t kRecentSamples = 64;
/// The smallest slice: one Ethernet frame's payload.
constexpr uint64_t kMinSliceBytes = 1500;

}  // namespace

ThrottledSource::ThrottledSource(std::shared_ptr<ByteSource> inner, const LinkModel& link)
    : inner_(std::move(inner)),
      link_(link),
      name_(fmt::format("{} (via {:g} Mbit/s, {:g} ms link)", inner_->name(), link.bits_per_s / 1e6,
                        link.rtt_s * 1e3)) {}

uint64_t ThrottledSource::sizeBytes() const {
  return inner_->sizeBytes();
}

const std::string& ThrottledSource::name() const {
  return name_;
}

LinkStatsTotal ThrottledSource::totals() const {
  std::lock_guard lock(mutex_);
  return totals_;
}

std::optional<LinkStats> ThrottledSource::linkStats() const {
  std::lock_guard lock(mutex_);
  LinkStats stats;
  stats.requests = totals_.reads;
  stats.bytes_received = totals_.bytes;
  stats.cancelled = totals_.reads_cancelled;
  stats.in_flight = in_flight_;
  stats.recent.assign(recent_.begin(), recent_.end());
  return stats;
}

bool ThrottledSource::waitUntil(Clock::time_point deadline, const std::atomic<bool>* cancel) const {
  std::unique_lock lock(mutex_);
  for (;;) {
    if (cancel && cancel->load(std::memory_order_acquire)) return false;
    const auto now = Clock::now();
    if (now >= deadline) return true;
    wait_.wait_until(lock, cancel ? std::min(deadline, now + kCancelCheck) : deadline);
  }
}

Result<void> ThrottledSource::transfer(uint64_t offset_bytes, std::span<uint8_t> out,
                                       const std::atomic<bool>* cancel) const {
  // A range past the end fails at once, as the inner source says, without using the link.
  if (offset_bytes > inner_->sizeBytes() || out.size() > inner_->sizeBytes() - offset_bytes)
    return inner_->read(offset_bytes, out);
  const Clock::time_point started = Clock::now();
  {
    std::lock_guard lock(mutex_);
    ++totals_.reads;
    ++in_flight_;
  }
  const double bytes_per_s = link_.bits_per_s / 8;
  const uint64_t slice =
      std::max<uint64_t>(kMinSliceBytes, uint64_t(std::llround(bytes_per_s * kSliceS)));
  uint64_t crossed = 0;
  auto cancelled = [&]() -> Result<void> {
    std::lock_guard lock(mutex_);
    --in_flight_;
    totals_.bytes += crossed;
    ++totals_.reads_cancelled;
    return fail(ErrorCode::kCancelled,
                fmt::format("{}: read at offset {} cancelled after {} of {} bytes", name_,
                            offset_bytes, crossed, out.size()));
  };
  // The request's trip out and the first byte's trip back.
  Clock::time_point due = started + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(link_.rtt_s));
  if (!waitUntil(due, cancel)) return cancelled();
  const double first_byte_s = std::chrono::duration<double>(Clock::now() - started).count();
  // Then the bytes, a slice at a time on the shared link: each read in flight reserves its
  // next slice only when its last one has crossed, so they take turns (fair sharing) and the
  // link never carries more than its rate. Slices are placed on the read's own timeline
  // (`due`), not at the moment its thread wakes: a thread the scheduler wakes late finds its
  // bytes arrived, as a socket's buffer would hold them, so a busy CPU does not slow the link.
  while (crossed < out.size()) {
    const uint64_t bytes = std::min<uint64_t>(slice, out.size() - crossed);
    {
      std::lock_guard lock(mutex_);
      const Clock::time_point begin = std::max(due, link_free_at_);
      due = begin + std::chrono::duration_cast<Clock::duration>(
                        std::chrono::duration<double>(double(bytes) / bytes_per_s));
      link_free_at_ = due;
    }
    if (!waitUntil(due, cancel)) return cancelled();
    crossed += bytes;
  }
  {
    std::lock_guard lock(mutex_);
    --in_flight_;
    totals_.bytes += crossed;
    const Clock::time_point finished = Clock::now();
    recent_.push_back({finished, crossed, std::chrono::duration<double>(finished - started).count(),
                       first_byte_s});
    while (recent_.size() > kRecentSamples) recent_.pop_front();
  }
  return inner_->read(offset_bytes, out);
}

Result<void> ThrottledSource::read(uint64_t offset_bytes, std::span<uint8_t> out) const {
  return transfer(offset_bytes, out, nullptr);
}

Result<void> ThrottledSource::readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                                              const std::atomic<bool>& cancel) const {
  return transfer(offset_bytes, out, &cancel);
}

std::shared_ptr<ThrottledSource> makeThrottledSource(std::shared_ptr<ByteSource> inner,
                                                     const LinkModel& link) {
  return std::make_shared<ThrottledSource>(std::move(inner), link);
}

}  // namespace tessera
