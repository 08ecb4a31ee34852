#pragma once
// Adaptive scheduling (Marvie & Bouatouch, "Remote Rendering of Massively Textured 3D Scenes
// Through Progressive Texture Maps", part III): which of the wanted tiles to request, given
// the link's measured throughput and latency, a client-memory budget and a time limit per
// level, with one set of budgets while the view moves and a wider one once it has been still
// for n seconds. Pure policy on the render thread: no threads, no I/O; time is passed in.

#include <chrono>
#include <cstdint>
#include <functional>
#include <span>
#include <unordered_set>
#include <vector>

#include "link_estimator.h"
#include <tessera/stream.h>

namespace tessera::detail {

/// What the streamer knows about one wanted tile.
struct TileFacts {
  bool held = false;           ///< loaded or resident: occupies memory, needs no transfer
  bool in_flight = false;      ///< being read: its bytes are on their way
  uint64_t payload_bytes = 0;  ///< what its transfer costs (an estimate when not yet known)
  /// payload_bytes is the tile's own (its directory entry was read), not an estimate: only
  /// then does a view's tile count towards the egress budget's base.
  bool payload_known = true;
  /// Dependent codecs (ptm; docs/runtime.md, "Dependent codecs"): whether the loader can
  /// decode the tile without loading its parent first, because the parent is in the host
  /// cache or on its way. True for a tile without a parent, and for every other codec.
  bool parent_ready = true;
};

class AdaptiveScheduler {
 public:
  using Clock = std::chrono::steady_clock;
  /// `tile_bytes`: a decoded tile's size; `cache_budget_bytes` caps every memory budget.
  AdaptiveScheduler(const AdaptiveOptions& options, uint32_t level_count, uint64_t tile_bytes,
                    uint64_t cache_budget_bytes);

  /// Chooses this frame's requests. `wanted`: every tile the residency wants, in priority
  /// order (held ones included). `requests`: on entry the wanted tiles that are neither
  /// loaded nor resident, in priority order; on return those to request. Levels are
  /// accepted coarse to fine while the visible tiles (urgency 0-1) each level still misses
  /// can arrive within the mode's time limit (link.bytesWithin) and everything accepted fits
  /// the memory budget; the first level that does not fit ends refinement. The coarsest
  /// level is always requested. Once every visible tile of the accepted levels has arrived,
  /// the rest of the clip regions and the prefetch (urgency 2-3) at accepted levels follow
  /// while the bytes on their way fit the time limit's bytes and the memory budget. A tile
  /// whose parent is not ready (TileFacts::parent_ready) and not requested this frame makes
  /// the loader queue the parent too: such a tile of the view counts the parent's decoded
  /// bytes in the memory, and one of the rest of the regions waits for its parent's request.
  /// Fills the adaptive fields of `report`.
  void schedule(const View& view, Clock::time_point now, const LinkEstimate& link,
                std::span<const TileRequest> wanted,
                const std::function<TileFacts(const TileId&)>& facts,
                std::vector<TileRequest>& requests, FrameReport& report);

 private:
  /// Updates the still/moving state with this frame's view; true when still.
  bool observe(const View& view, Clock::time_point now);

  /// Whether a tile beyond the view of `payload_bytes` still fits the egress budget.
  bool egressAllows(uint64_t payload_bytes) const;

  /// Counts a tile requested for the first time into the flight's egress totals.
  void countEgress(const TileRequest& request, uint64_t payload_bytes);

  AdaptiveOptions options_;
  uint32_t level_count_;
  uint64_t tile_bytes_;
  uint64_t cache_budget_bytes_;
  bool have_view_ = false;
  View last_view_;
  Clock::time_point last_change_{};
  /// Last frame's finest requested level and the conditions it was chosen under: a level
  /// already being fetched is kept unless it overshoots its budget by kKeepFactor, so small
  /// swings of the estimate do not cancel and re-request the same tiles.
  uint32_t last_level_ = UINT32_MAX;
  bool last_still_ = false;
  std::vector<uint64_t> missing_bytes_, level_memory_;
  std::vector<TileFacts> facts_;
  std::unordered_set<TileId, TileIdHash> admitted_;  ///< this frame's requests so far
  /// Egress over the flight: the tiles counted (each once, so a tile wanted or requested on
  /// many frames is charged once) and the totals.
  std::unordered_set<TileId, TileIdHash> counted_;
  uint64_t view_bytes_ = 0, view_tiles_ = 0, prefetch_bytes_ = 0, prefetch_tiles_ = 0;
};

}  // namespace tessera::detail
