#pragma once
// `tessera view`, callable from other commands (`tessera demo --view`).

#include <cstdint>
#include <string>
#include <vector>

namespace tessera::cli {

/// Every option of `tessera view` (docs/view.md).
struct ViewArgs {
  std::string archive;
  std::string renderer = "tile-quads";
  uint32_t image = 0;
  std::string size = "1280x720";
  size_t cache_mib = 512;
  bool perspective = false;
  std::string screenshot_dir = ".";
  /// Overlays on from the start: any of "levels", "clip", "grid" (also toggled by L, C, G).
  std::vector<std::string> overlays;
  /// A simulated network link "RATE:RTT" between the archive and the viewer (as `fly --link`).
  std::string link;
  /// Adaptive scheduling: "auto" (on over --link), "on" or "off".
  std::string adaptive = "auto";
  /// What adaptive scheduling fetches beyond the view (parseEgressBudget).
  std::string egress = "default";
  /// Display window of 16-bit and float images (display_window_option.h).
  std::string window = "auto";
  std::string gamma = "1";
  uint64_t frames = 0;  ///< hidden, for tests: quit after this many frames (0 = run)
};

/// Opens the window and runs until it closes. Returns the command's exit code, having printed
/// any error (no display included).
int runView(const ViewArgs& args);

}  // namespace tessera::cli
