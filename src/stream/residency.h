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
  /// A view equal to the last one, once the plan has settled (no motion since the frame
  /// before, no clip centre still stepping towards its target), reuses the last plan: it
  /// would come out the same.
  const ResidencyPlan& plan(const View& view);
  /// Plans computed so far (calls of plan() that did not reuse the last one).
  uint64_t plansComputed() const { return plans_computed_; }

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
  /// What plan() works from this frame.
  struct FrameState {
    Footprint fp;
    uint32_t desired = 0;                         ///< the footprint's desired level
    uint32_t n = 0;                               ///< clip-region side (eq. 3)
    double prev_centre_x = 0, prev_centre_y = 0;  ///< the last frame's footprint centre
    bool first_frame = true;                      ///< no centre yet at the desired level
  };

  void updateCentre(uint32_t level, double f_x, double f_y, uint32_t n, bool limit_step);
  void addWanted(const TileId& tile, int cls, double distance, bool prefetch, bool ahead);
  TileRect gridRect(uint32_t level) const;
  // The steps of plan(), in order; each adds to plan_ from frame_.
  /// Distance of a tile's centre from the view centre, in tiles of its level.
  double distanceFromCentre(const TileId& tile) const;
  /// Every tile of `rect` (clipped to the grid) at `level`, in class `cls`.
  void addRect(uint32_t level, const TileRect& rect, int cls, bool prefetch, bool ahead = false);
  void addVisibleOrtho();
  void addVisiblePerspective(const View& view);
  /// True when the view centre moved a whole clip region or more since the last frame.
  bool jumpedThisFrame() const;
  void addLookahead();
  /// Class 2 and the keep regions; returns the desired level's clip region.
  TileRect addClipRegions();
  void addPrefetch(const TileRect& clip);
  /// Sorts the wanted set, keeps each tile's best priority, and fills the motion.
  void finishPlan();

  ImageInfo info_;
  uint32_t image_;
  ResidencyOptions options_;
  std::vector<LevelCentre> centres_;
  std::vector<LevelCentre> centres_before_;  ///< scratch of plan(): centres at its start
  ResidencyPlan plan_;
  FrameState frame_;
  double last_centre_x_ = 0, last_centre_y_ = 0;  ///< the footprint centre of the last plan
  std::unordered_map<TileId, double, TileIdHash> wanted_index_;
  std::vector<TileRect> keep_rects_;  ///< per level, in tiles
  View last_view_;                    ///< the view of the last plan computed
  bool has_last_view_ = false;
  /// The last plan saw the same view as the one before it and moved no clip centre: the
  /// same view again gives the same plan.
  bool settled_ = false;
  uint64_t plans_computed_ = 0;
};

}  // namespace tessera::detail
