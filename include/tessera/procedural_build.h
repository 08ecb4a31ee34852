#pragma once
/// \file
/// Building a mixed archive (format 1.1) from a brush database: every tile of every level is
/// analysed (Demeulemeester et al., section 2), composited, encoded, and stored either baked or
/// procedural, whichever minimises the archive under the compositing-time budget
/// (docs/procedural.md, "The analysis phase").

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/procedural.h>
#include <tessera/result.h>

namespace tessera {

/// An area whose levels finer than `finest_level` are not stored (seed 001: tiles that scene
/// analysis showed are never seen that close); its tiles of those levels are left empty, and
/// there instances much smaller than a texel of `finest_level` are dropped from every level.
struct DetailRegion {
  BoxPx area;  ///< level-0 texels
  uint32_t finest_level = 0;
};

/// What `tessera build --procedural` can set. Defaults are the CLI's.
struct ProceduralBuildOptions {
  std::string database;  ///< SQLite file or PostGIS connection (openBrushDatabase)
  std::string output;    ///< written atomically
  /// Optional underlying layer: a height image (TIFF, PNG, JPEG; its first channel) stretched
  /// over the texture, read by masked brushes. Sets the texture size when the database has none.
  std::string base;
  uint32_t tile_size_px = 256;
  uint32_t border_px = 0;
  Codec codec = Codec::kJpeg;  ///< for baked tiles; not ptm (its tiles need baked parents)
  int quality = 85;
  int effort = 0;
  Codec brush_codec = Codec::kZstd;  ///< lossless, for brush images and the layer
  uint32_t threads = 0;              ///< 0 = all cores
  uint32_t page_tiles_log2 = 5;
  TileOrder order = TileOrder::kHilbert;
  /// Seed 001, section 2.2: the per-tile budget is frame_budget_ms / max_new_tiles_per_frame.
  double frame_budget_ms = 4.0;
  uint32_t max_new_tiles_per_frame = 4;
  /// Cost model of the compositor (docs/procedural.md, "Compositing time").
  double cost_tile_ns = 15000;
  double cost_instance_ns = 250;
  double cost_texel_ns = 4.5;
  /// Instances whose diameter is below this fraction of a texel of the finest stored level
  /// over them are dropped (0 disables).
  double small_instance_texels = 0.25;
  std::vector<DetailRegion> detail_regions;
  /// Store every tile baked (the comparison archive); the report still says what the choice
  /// would have saved.
  bool bake_all = false;
};

struct ProceduralBuildProgress {
  uint64_t tiles_done = 0;
  uint64_t tiles_total = 0;
  double elapsed_s = 0;
};

/// What a mixed build did and chose.
struct ProceduralBuildReport {
  uint64_t tiles_total = 0;
  uint64_t tiles_procedural = 0;
  uint64_t tiles_baked = 0;        ///< encoded payloads
  uint64_t tiles_uniform = 0;      ///< baked as one colour (no payload)
  uint64_t tiles_empty = 0;        ///< nothing drawn, or dropped by a detail region
  uint64_t tiles_dropped = 0;      ///< of tiles_empty: levels a detail region does not store
  uint64_t tiles_over_budget = 0;  ///< would have been procedural but composite too slowly
  uint64_t instances = 0;          ///< in the database
  uint64_t instances_queried = 0;  ///< summed over tiles
  uint64_t instances_covered = 0;  ///< dropped by culling, summed over tiles
  uint64_t instances_small = 0;    ///< dropped as much smaller than a texel, summed over tiles
  uint64_t baked_payload_bytes = 0;
  uint64_t procedural_page_bytes = 0;  ///< pages written (identical pages stored once)
  uint64_t brush_bytes = 0;            ///< brush images and layer stored (once)
  /// Payload bytes had every tile been baked: the archive this one is compared with.
  uint64_t all_baked_payload_bytes = 0;
  int64_t bytes_saved = 0;  ///< all_baked_payload_bytes minus what this archive stores
  double tile_budget_ms = 0;
  double worst_estimated_ms = 0;  ///< of the procedural tiles, by the cost model
  double worst_measured_ms = 0;   ///< of the procedural tiles, composited during the build
  double mean_query_us = 0;       ///< the spatial query per tile
  uint64_t output_bytes = 0;
  double elapsed_s = 0;
  ImageInfo image;
};

/// Builds the mixed archive. Nothing is left at `options.output` on failure or cancellation.
/// Errors name the database, the tile or the file. Blocking; owned by the caller's thread.
[[nodiscard]] Result<ProceduralBuildReport> buildProceduralArchive(
    const ProceduralBuildOptions& options,
    const std::function<void(const ProceduralBuildProgress&)>& on_progress = {},
    const std::atomic<bool>* cancel = nullptr);

/// Reads a whole picture (TIFF, PNG, JPEG) as RGBA (alpha 255 where it has none), with the
/// builder's readers: for brush images, which are small (at most kMaxBrushSidePx a side, else
/// kTooLarge). A temporary archive goes to `scratch_dir` and is removed. Errors name `path`.
[[nodiscard]] Result<Image> readImageRgba(const std::string& path, const std::string& scratch_dir);

}  // namespace tessera
