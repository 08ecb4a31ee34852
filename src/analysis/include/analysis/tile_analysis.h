#pragma once
// The analysis phase for one tile (Demeulemeester et al., section 2): of the instances a spatial
// query found, keep those that contribute a texel (2.1), drop those much smaller than a texel
// only where finer levels are not stored (2.1, no discontinuity between levels), and estimate
// the compositing time against the per-tile budget (2.2).

#include <cstdint>
#include <span>
#include <vector>

#include <tessera/procedural.h>

namespace tessera::detail {

/// Where the finer levels are not stored (seed 001: tiles of finer levels "thrown away" by
/// scene analysis): per cell of `cell_px` level-0 texels, the finest level stored there. Cells
/// outside the grid, or an empty map, store every level (0).
struct DetailMap {
  uint32_t cell_px = 0;
  uint32_t columns = 0;
  uint32_t rows = 0;
  std::vector<uint8_t> finest_level;  ///< columns * rows, row-major

  /// The finest level stored anywhere in `box` (the minimum over the cells it meets).
  uint32_t finestLevelIn(const BoxPx& box) const;
  /// True when no cell under the tile's level-0 area stores `level` or a coarser one, i.e.
  /// the tile is dropped.
  bool dropsTile(const BoxPx& tile_area, uint32_t level) const {
    return level < finestLevelIn(tile_area);
  }
};

/// Compositing time of a tile, estimated from what the compositor does: a fixed cost, one per
/// instance (setup) and one per texel visited (the spans within each instance's reach).
/// Calibrated on this machine by bench/procedural_bench (docs/procedural.md, "Figures").
struct CostModel {
  double tile_ns = 15000;
  double instance_ns = 250;
  double texel_ns = 4.5;
  double estimateMs(uint64_t instances, uint64_t visited_texels) const {
    return (tile_ns + instance_ns * double(instances) + texel_ns * double(visited_texels)) * 1e-6;
  }
};

struct AnalysisRules {
  /// An instance whose diameter is below this fraction of a texel of the finest level stored
  /// over it is dropped at every level (0 disables the rule).
  double small_instance_texels = 0.25;
  const DetailMap* detail = nullptr;  ///< null: every level stored everywhere
  CostModel cost;
  /// Seed 001's conservative rule: the frame's compositing budget divided by the most new
  /// tiles a frame can bring.
  double tile_budget_ms = 1.0;
};

struct TileAnalysis {
  std::vector<BrushInstance> kept;  ///< contributing instances, drawing order
  std::vector<TileClip> clips;      ///< per kept instance: where it is not replaced from above
  uint64_t covered = 0;             ///< dropped: no texel survives the opaque ones above
  uint64_t small = 0;               ///< dropped: much smaller than a texel where finer is dropped
  uint64_t visited_texels = 0;      ///< the compositor's work for `kept` (clip areas)
  double estimated_ms = 0;
  bool within_budget = true;
};

/// True when the instance is dropped everywhere by the small-instance rule.
bool isNegligibleInstance(const BrushInstance& instance, const AnalysisRules& rules);

/// Analyses one tile. `candidates` are the spatial query's result for tileQueryBox(tile), in
/// drawing order. Fails when an instance names a brush the set lacks.
Result<TileAnalysis> analyseTile(const BrushSet& brushes, const TileGeometry& tile,
                                 std::span<const BrushInstance> candidates,
                                 const AnalysisRules& rules);

}  // namespace tessera::detail
