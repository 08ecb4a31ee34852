#pragma once
// Cutting stored tiles (borders and padding included) out of a level's band of rows.

#include <cstdint>

#include <tessera/format.h>

namespace tessera::detail {

/// The rows of one level that a band currently holds. `row(y)` is valid for the rows the
/// pyramid builder guarantees when it announces a tile row.
class LevelRows {
 public:
  virtual ~LevelRows() = default;
  virtual const uint8_t* row(uint32_t y) const = 0;
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t channels = 0;
  SampleType sample_type = SampleType::kU8;
};

/// Writes tile (x, y) of a level with `tile_size_px` and `border_px` into `out`
/// ((tile + 2 * border)^2 texels). Texels outside the level, in the padding of
/// Backes et al. eq. 1 or in the border at the image edge, replicate the nearest edge texel.
void cutTile(const LevelRows& rows, uint32_t tile_size_px, uint32_t border_px, uint32_t x,
             uint32_t y, uint8_t* out);

}  // namespace tessera::detail
