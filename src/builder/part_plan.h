#pragma once
// How a split build divides an image (docs/builder.md, "Split and merge"): the base level is
// cut into bands of whole tile rows of level M - 1, so that every level below M is tile-aligned
// in each band, and part p of N gets bands [p * B / N, (p + 1) * B / N). Parts build levels
// below M; the merge builds levels M and up from the exact level-M rows each part stores.

#include <algorithm>
#include <cstdint>

#include <tessera/format.h>

namespace tessera::detail {

struct PartPlan {
  uint32_t merge_level = 0;  ///< M: the first level the merge computes
  uint32_t band_rows = 0;    ///< level-0 rows per band: 2^(M-1) x tile, or the height if M = 0
  uint32_t band_count = 0;
  uint32_t part_count = 0;
  uint32_t height_px = 0;

  /// Level-0 rows of part `p` (0-based): [firstRow(p), firstRow(p + 1)).
  uint32_t firstRow(uint32_t p) const {
    const uint64_t band = uint64_t(p) * band_count / part_count;
    return uint32_t(std::min<uint64_t>(height_px, band * band_rows));
  }
};

/// Levels below M split into at least 4 bands per part where the image allows it (the bands
/// then balance the parts to within a quarter of a share), M as high as that allows so the
/// merge's share stays small; M = 0 for a single-tile image.
inline PartPlan planParts(const ImageInfo& info, uint32_t part_count) {
  PartPlan plan;
  plan.part_count = part_count;
  plan.height_px = info.height_px;
  if (info.level_count <= 1) {
    plan.band_rows = info.height_px;
    plan.band_count = 1;
    return plan;
  }
  plan.merge_level = 1;
  for (uint32_t m = 2; m < info.level_count; ++m)
    if (info.tilesY(m - 1) >= 4ull * part_count) plan.merge_level = m;
  plan.band_rows = info.tile_size_px << (plan.merge_level - 1);
  plan.band_count = info.tilesY(plan.merge_level - 1);
  return plan;
}

/// Tile rows of `level` whose base rows start in [first_row, end_row), given that first_row is
/// a band boundary: ceil-divided so the image's last, partial tile row counts.
inline uint32_t tileRowAt(const ImageInfo& info, uint32_t level, uint32_t row) {
  const uint64_t span = uint64_t(info.tile_size_px) << level;
  return uint32_t((row + span - 1) / span);
}

}  // namespace tessera::detail
