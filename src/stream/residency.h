#pragma once
// The residency manager: turns a view into what must be loaded, uploaded and released.
// Pure policy (no threads, no I/O, no GPU): Backes et al. sections 5-6 (clip regions of
// eq. 3-4 around each level's centre, effective-region hysteresis, start level eq. 7,
// coarsest level always resident, parent before child) with Luo & Duan section 3.3
// (direction-based prefetch, maximum centre offset per frame). Owned by the render thread.

#include <cstdint>
#include <functional>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <tessera/cache.h>
#include <tessera/stream.h>

#include "stream/footprint.h"

namespace tessera::detail {

/// Everything the manager decided for one frame.
struct ResidencyPlan {
  uint32_t desired_level = 0;
  std::vector<FrameUpdate::LevelRegion> clip_regions;  ///< per level, clipped to the grid
  std::vector<TileRequest> wanted;  ///< every tile wanted, sorted by priority (includes loaded)
  std::vector<TileId> visible;      ///< tiles at their required level that the view shows
  ViewerMotion motion;              ///< for the cache's eviction policy
};

class ResidencyManager {
 public:
  ResidencyManager(const ImageInfo& info, uint32_t image, const ResidencyOptions& options);

  /// Recomputes clip regions (with hysteresis and the per-frame centre limit) and the
  /// wanted set with priorities: class 0 the coarsest level, class 1 visible tiles (then
  /// those the lookahead expects on screen soon), class 2 the rest of the clip regions,
  /// class 3 prefetch; within each coarse levels first, then nearer the view centre first.
  const ResidencyPlan& plan(const View& view);

  /// True when `tile` is in the current wanted set.
  bool isWanted(const TileId& tile) const;
  /// Priority of a wanted tile (lower is sooner), or a large value if unwanted.
  double priorityOf(const TileId& tile) const;

  /// Which tiles cover the view: `resident(tile)` tells whether a tile is on the GPU.
  /// Fills coverage fields of `report`.
  void measureCoverage(const std::function<bool(const TileId&)>& resident,
                       FrameReport& report) const;

  /// The tiles of the clip regions expanded by the keep margin: resident tiles outside them
  /// are released.
  bool isKept(const TileId& tile) const;

  uint32_t levelCount() const { return info_.level_count; }

 private:
  struct LevelCentre {
    bool valid = false;
    int64_t x = 0, y = 0;  ///< clip-region centre tile (eq. 4)
    int64_t prev_x = 0, prev_y = 0;
  };
  void updateCentre(uint32_t level, double f_x, double f_y, uint32_t n, bool limit_step);
  void addWanted(const TileId& tile, int cls, double distance, bool prefetch, bool ahead);
  TileRect gridRect(uint32_t level) const;

  ImageInfo info_;
  uint32_t image_;
  ResidencyOptions options_;
  std::vector<LevelCentre> centres_;
  ResidencyPlan plan_;
  View last_view_;
  Footprint footprint_;
  std::unordered_map<TileId, double, TileIdHash> wanted_index_;
  std::vector<TileRect> keep_rects_;  ///< per level, in tiles
};

}  // namespace tessera::detail
