// The link estimator: throughput over busy time, latency as a min-filter, queue wait as a
// moving average (docs/runtime.md, "Measuring the link").
#include "link_estimator.h"

#include <algorithm>
#include <cmath>

namespace tessera::detail {

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

}  // namespace tessera::detail
