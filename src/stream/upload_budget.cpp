#include "upload_budget.h"

#include <algorithm>
#include <cmath>

namespace tessera::detail {

UploadBudgetController::UploadBudgetController(const ResidencyOptions& options)
    : options_(options.adaptive_upload), fixed_bytes_(options.upload_budget_bytes) {
  smoothed_bytes_ = std::max(options_.initial_bytes_per_ms, 1.0);
  smoothed_ms_ = 1;
}

void UploadBudgetController::observe(uint64_t bytes, double ms) {
  if (bytes == 0 || !(ms >= 0) || !std::isfinite(ms)) return;
  const double weight = std::clamp(options_.smoothing, 0.0, 1.0);
  const double sample_ms = std::max(ms, 1e-3);
  // The first measurement replaces the initial guess: the guess is no evidence.
  const double w = samples_ == 0 ? 1.0 : weight;
  smoothed_bytes_ += w * (double(bytes) - smoothed_bytes_);
  smoothed_ms_ += w * (sample_ms - smoothed_ms_);
  ++samples_;
}

uint64_t UploadBudgetController::budgetBytes() const {
  if (!options_.enabled) return fixed_bytes_;
  const double share_ms =
      std::max(options_.frame_ms, 0.0) * std::clamp(options_.upload_share, 0.0, 1.0);
  const double bytes = bytesPerMs() * share_ms;
  const uint64_t lo = std::max<uint64_t>(options_.min_bytes, 1);
  const uint64_t hi = std::max(options_.max_bytes, lo);
  if (!(bytes < double(hi))) return hi;
  return std::clamp(uint64_t(bytes), lo, hi);
}

}  // namespace tessera::detail
