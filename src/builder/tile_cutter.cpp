#include "tile_cutter.h"

#include <algorithm>
#include <cstring>

namespace tessera::detail {

void cutTile(const LevelRows& rows, uint32_t tile_size_px, uint32_t border_px, uint32_t x,
             uint32_t y, uint8_t* out) {
  const int64_t side = tile_size_px + 2 * border_px;
  // Copies whole texels, whatever their sample type.
  const int64_t channels = int64_t(rows.channels) * sampleBytes(rows.sample_type);
  const int64_t width = rows.width_px, height = rows.height_px;
  const int64_t x0 = int64_t(x) * tile_size_px - border_px;
  const int64_t y0 = int64_t(y) * tile_size_px - border_px;
  // Columns [inside_begin, inside_end) of the tile come straight from the row.
  const int64_t inside_begin = std::clamp<int64_t>(-x0, 0, side);
  const int64_t inside_end = std::clamp<int64_t>(width - x0, inside_begin, side);
  for (int64_t sy = 0; sy < side; ++sy) {
    const uint8_t* src = rows.row(uint32_t(std::clamp<int64_t>(y0 + sy, 0, height - 1)));
    uint8_t* dst = out + sy * side * channels;
    for (int64_t sx = 0; sx < inside_begin; ++sx) std::memcpy(dst + sx * channels, src, channels);
    if (inside_end > inside_begin)
      std::memcpy(dst + inside_begin * channels, src + (x0 + inside_begin) * channels,
                  (inside_end - inside_begin) * channels);
    const uint8_t* last = src + (width - 1) * channels;
    for (int64_t sx = inside_end; sx < side; ++sx) std::memcpy(dst + sx * channels, last, channels);
  }
}

}  // namespace tessera::detail
