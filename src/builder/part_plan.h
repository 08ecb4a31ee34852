#pragma once
// How a split build divides an image (docs/builder.md, "Split and merge"): the base level is
// cut into bands of whole tile rows of level M - 1, so that every level below M is tile-aligned
// in each band, and part p of N gets bands [p * B / N, (p + 1) * B / N). Parts build levels
// below M; the merge builds levels M and up from the exact level-M rows each part stores.

#include <algorithm>
#include <cmath>
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

/// M minimises the estimated time of the slowest part plus the merge, in units of the base
/// level's work: a part reads its share of the bands (rounded up, plus a band on each side
/// for borders), and the merge computes the 4^-M x 4/3 of the pixels above the parts on one
/// thread, counted twice against the parts' all-core encoding. M = 0 for a single-tile image.
inline PartPlan planParts(const ImageInfo& info, uint32_t part_count) {
  PartPlan plan;
  plan.part_count = part_count;
  plan.height_px = info.height_px;
  if (info.level_count <= 1) {
    plan.band_rows = info.height_px;
    plan.band_count = 1;
    return plan;
  }
  double best = 0;
  for (uint32_t m = 1; m < info.level_count; ++m) {
    const double bands = info.tilesY(m - 1);
    const double share = std::ceil(bands / part_count) + (info.border_px > 0 ? 2 : 0);
    const double cost =
        std::min(share, bands) / bands + 2.0 * (4.0 / 3.0) * std::pow(4.0, -double(m));
    if (m == 1 || cost < best) {
      best = cost;
      plan.merge_level = m;
    }
  }
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
