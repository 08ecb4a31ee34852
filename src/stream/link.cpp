// The simulated link and the --link syntax (Marvie & Bouatouch, part III, measured their
// adaptation over simulated bandwidth too).
#include <tessera/link.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <mutex>

#include <fmt/format.h>

namespace tessera {

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

using Clock = std::chrono::steady_clock;

}  // namespace

struct ThrottledSource::State {
  mutable std::mutex mutex;              // guards everything below
  mutable std::condition_variable wait;  ///< timed waits only
  Clock::time_point link_free_at{};      ///< the link carries reserved slices until then
  LinkStatsTotal totals;
  uint32_t in_flight = 0;
  std::deque<LinkSample> recent;

  /// Waits until `deadline`; false as soon as `cancel` is seen set. Nothing signals a bare
  /// atomic flag, so the wait looks at it every kCancelCheck, as a network client looks
  /// between two receives.
  bool waitUntil(Clock::time_point deadline, const std::atomic<bool>* cancel) const {
    std::unique_lock lock(mutex);
    for (;;) {
      if (cancel && cancel->load(std::memory_order_acquire)) return false;
      const auto now = Clock::now();
      if (now >= deadline) return true;
      wait.wait_until(lock, cancel ? std::min(deadline, now + kCancelCheck) : deadline);
    }
  }
};

ThrottledSource::ThrottledSource(std::shared_ptr<ByteSource> inner, const LinkModel& link)
    : inner_(std::move(inner)),
      link_(link),
      name_(fmt::format("{} (via {:g} Mbit/s, {:g} ms link)", inner_->name(), link.bits_per_s / 1e6,
                        link.rtt_s * 1e3)),
      state_(std::make_unique<State>()) {}

ThrottledSource::~ThrottledSource() = default;

uint64_t ThrottledSource::sizeBytes() const {
  return inner_->sizeBytes();
}

const std::string& ThrottledSource::name() const {
  return name_;
}

LinkStatsTotal ThrottledSource::totals() const {
  std::lock_guard lock(state_->mutex);
  return state_->totals;
}

std::optional<LinkStats> ThrottledSource::linkStats() const {
  std::lock_guard lock(state_->mutex);
  LinkStats stats;
  stats.requests = state_->totals.reads;
  stats.bytes_received = state_->totals.bytes;
  stats.cancelled = state_->totals.reads_cancelled;
  stats.in_flight = state_->in_flight;
  stats.recent.assign(state_->recent.begin(), state_->recent.end());
  return stats;
}

Result<void> ThrottledSource::transfer(uint64_t offset_bytes, std::span<uint8_t> out,
                                       const std::atomic<bool>* cancel) const {
  // A range past the end fails at once, as the inner source says, without using the link.
  if (offset_bytes > inner_->sizeBytes() || out.size() > inner_->sizeBytes() - offset_bytes)
    return inner_->read(offset_bytes, out);
  State& state = *state_;
  const Clock::time_point started = Clock::now();
  {
    std::lock_guard lock(state.mutex);
    ++state.totals.reads;
    ++state.in_flight;
  }
  const double bytes_per_s = link_.bits_per_s / 8;
  const uint64_t slice =
      std::max<uint64_t>(kMinSliceBytes, uint64_t(std::llround(bytes_per_s * kSliceS)));
  uint64_t crossed = 0;
  auto cancelled = [&]() -> Result<void> {
    std::lock_guard lock(state.mutex);
    --state.in_flight;
    state.totals.bytes += crossed;
    ++state.totals.reads_cancelled;
    return fail(ErrorCode::kCancelled,
                fmt::format("{}: read at offset {} cancelled after {} of {} bytes", name_,
                            offset_bytes, crossed, out.size()));
  };
  // The request's trip out and the first byte's trip back.
  Clock::time_point due = started + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(link_.rtt_s));
  if (!state.waitUntil(due, cancel)) return cancelled();
  const double first_byte_s = std::chrono::duration<double>(Clock::now() - started).count();
  // Then the bytes, a slice at a time on the shared link: each read in flight reserves its
  // next slice only when its last one has crossed, so they take turns (fair sharing) and the
  // link never carries more than its rate. Slices are placed on the read's own timeline
  // (`due`), not at the moment its thread wakes: a thread the scheduler wakes late finds its
  // bytes arrived, as a socket's buffer would hold them, so a busy CPU does not slow the link.
  while (crossed < out.size()) {
    const uint64_t bytes = std::min<uint64_t>(slice, out.size() - crossed);
    {
      std::lock_guard lock(state.mutex);
      const Clock::time_point begin = std::max(due, state.link_free_at);
      due = begin + std::chrono::duration_cast<Clock::duration>(
                        std::chrono::duration<double>(double(bytes) / bytes_per_s));
      state.link_free_at = due;
    }
    if (!state.waitUntil(due, cancel)) return cancelled();
    crossed += bytes;
  }
  {
    std::lock_guard lock(state.mutex);
    --state.in_flight;
    state.totals.bytes += crossed;
    const Clock::time_point finished = Clock::now();
    state.recent.push_back({finished, crossed,
                            std::chrono::duration<double>(finished - started).count(),
                            first_byte_s});
    while (state.recent.size() > kRecentSamples) state.recent.pop_front();
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
