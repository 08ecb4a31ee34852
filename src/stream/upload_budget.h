#pragma once
// The per-frame upload budget that follows what uploads cost on this machine
// (docs/runtime.md, "Upload budget"): a smoothed estimate of the renderer's upload rate, in
// bytes per render-thread millisecond, times the share of the frame uploads may take. A
// software renderer that copies 0.7 GB/s gets a few MiB a frame at 30 fps; a GPU whose
// uploads are a memcpy into a mapped buffer gets the maximum. Plain CPU class: fed measured
// timings, it is tested without a GPU or a clock.

#include <cstdint>

#include <tessera/stream.h>

namespace tessera::detail {

/// Owned by one thread (the render thread, through TileStreamer).
class UploadBudgetController {
 public:
  explicit UploadBudgetController(const ResidencyOptions& options);

  /// One frame's uploads: `bytes` texel bytes took `ms` render-thread milliseconds in the
  /// renderer. Frames that uploaded nothing say nothing about the rate and are ignored; a
  /// time of 0 (a clock too coarse) counts as a microsecond.
  void observe(uint64_t bytes, double ms);
  /// The texel bytes the next frame may hand to the renderer: the fixed
  /// `upload_budget_bytes` when adaptation is off, else the estimated rate times
  /// frame_ms * upload_share, clamped to [min_bytes, max_bytes]. 0 means no byte limit
  /// (fixed budget of 0).
  uint64_t budgetBytes() const;
  /// The smoothed upload rate, bytes per millisecond (the initial guess before any sample).
  double bytesPerMs() const { return smoothed_bytes_ / smoothed_ms_; }
  /// Frames observed so far.
  uint64_t samples() const { return samples_; }

 private:
  AdaptiveUploadOptions options_;
  uint64_t fixed_bytes_ = 0;
  // Exponentially smoothed bytes and milliseconds of the frames that uploaded: their ratio
  // weighs a frame by its size, so a frame of one small tile (whose time is mostly fixed
  // cost and clock noise) moves the estimate less than a frame of fifty.
  double smoothed_bytes_ = 0;
  double smoothed_ms_ = 1;
  uint64_t samples_ = 0;
};

}  // namespace tessera::detail
