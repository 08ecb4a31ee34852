#pragma once
// `tessera fly`, callable from other commands (`tessera demo` flies its standard paths).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <tessera/stream.h>

namespace tessera::cli {

/// Every option of `tessera fly` (docs/fly.md).
struct FlyArgs {
  std::string archive;
  std::string path = "pan";
  double speed_px_s = 1000;
  double duration_s = 10;
  std::string viewport = "1920x1080";
  double fps = 60;
  size_t cache_mib = 512;
  std::string eviction = "viewer-shift";
  uint32_t threads = 0;
  uint32_t upload_budget = ResidencyOptions{}.upload_budget_tiles;
  /// A fixed byte budget per frame (0 = no byte limit). Unset: with --render the budget
  /// follows the renderer's measured upload cost at the --fps frame target; without, the
  /// streamer's fixed default (no renderer, no cost to measure).
  std::optional<uint64_t> upload_budget_mib;
  /// With --render, draw every frame of the path however long each takes (the flight then
  /// runs slower than real time); by default frames that come while the GPU is still busy
  /// are skipped, as a display drops them.
  bool every_frame = false;
  /// Unset: StreamerOptions' default, or tuneForRemoteSource's for a URL or --link.
  std::optional<uint64_t> merge_gap_kib;
  uint64_t read_ahead_kib = StreamerOptions{}.read_ahead_bytes >> 10;
  std::optional<uint64_t> batch_gap_kib;  ///< unset: StreamerOptions' default, or the remote one
  std::optional<uint64_t> max_read_kib;   ///< unset: likewise
  std::string loader_priority = "auto";   ///< auto, idle or nice: LoaderPriority
  uint32_t image = 0;
  /// With --render: the display window of 16-bit and float images (display_window_option.h).
  std::string window = "auto";
  std::string gamma = "1";
  std::string out_dir = "fly-out";
  bool json = false;
  bool quiet = false;
  bool cold = false;
  bool decode_bound = false;
  std::string render = "none";
  /// "bc1": the loaders encode JPEG tiles to bc1 and tile quads draw them from a bc1 array
  /// (StreamerOptions::transcode_to_bc1); "none": tiles as the archive stores them.
  std::string transcode = "none";
  /// Where procedural tiles are composited: "cpu" (the loader threads) or "gpu" (a thread
  /// with a headless context, docs/procedural.md "GPU compositing").
  std::string composite = "cpu";
  std::vector<uint64_t> screenshot_frames;
  bool report = false;
  /// A simulated link between the archive and the loader, "RATE:RTT" (e.g. "20mbit:40ms");
  /// empty: the file directly.
  std::string link;
  /// Adaptive scheduling: "auto" (on over --link, off for a local file), "on" or "off".
  std::string adaptive = "auto";
  /// Seconds the view must be still before the still budgets apply (AdaptiveOptions).
  double still_after_s = AdaptiveOptions{}.still_after_s;
  /// What adaptive scheduling may fetch beyond the view (parseEgressBudget): default, metered,
  /// unbounded or a factor; and absolute caps over the flight (0: none).
  std::string egress = "default";
  uint64_t prefetch_max_kib = 0;
  uint64_t prefetch_max_requests = 0;
};

/// Flies and writes frames.csv, summary.json (and with `report`, report.html) to `out_dir`.
/// Returns the command's exit code, having printed any error.
int runFly(const FlyArgs& args);

}  // namespace tessera::cli
