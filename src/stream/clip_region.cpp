// Clip-region arithmetic of Backes et al., section 5 (eq. 3, 4, 5 and 7).
#include <tessera/stream.h>

#include <algorithm>
#include <bit>
#include <cmath>

namespace tessera {

uint32_t clipRegionTiles(uint32_t screen_w, uint32_t screen_h, uint32_t tile_size_px) {
  uint32_t longest = std::max(screen_w, screen_h);
  return std::max(1u, (longest + tile_size_px - 1) / tile_size_px) * 2;  // eq. 3
}

uint64_t residentTilesBound(const ImageInfo& info, uint32_t viewport_w, uint32_t viewport_h,
                            const ResidencyOptions& options) {
  const uint64_t side = clipRegionTiles(viewport_w, viewport_h, info.tile_size_px) +
                        2 * uint64_t(options.keep_margin_tiles);
  uint64_t bound = 0;
  for (uint32_t level = 0; level < info.level_count; ++level)
    bound += std::min(side * side, uint64_t(info.tilesX(level)) * info.tilesY(level));
  return bound;
}

int64_t clipCentreTile(double f_level_px, uint32_t tile_size_px) {
  return int64_t(std::floor(f_level_px / tile_size_px));  // eq. 4
}

TileRect clipRegionAround(int64_t centre_x, int64_t centre_y, uint32_t n) {
  int64_t half = n / 2;
  return {centre_x - half, centre_y - half, centre_x - half + n, centre_y - half + n};
}

uint32_t desiredLevelFor(double texels_per_pixel, uint32_t level_count) {
  if (!(texels_per_pixel > 1)) return 0;  // magnified, or NaN: the finest level
  // A tiny tolerance so exactly 2^L texels per pixel selects L despite rounding.
  double level = std::floor(std::log2(texels_per_pixel) + 1e-9);
  return uint32_t(std::clamp(level, 0.0, double(level_count - 1)));
}

uint32_t startLevelFor(uint32_t level, uint32_t n, uint32_t level_count) {
  uint32_t steps = uint32_t(std::bit_width(std::max(n, 1u) - 1));  // ceil(log2(n))
  return std::min(level + steps, level_count - 1);                 // eq. 7
}

}  // namespace tessera
