#pragma once
// What a view covers of an image, level by level: the residency manager's input, and what a
// renderer needs to choose the tiles it draws. Pure (no threads, no I/O).

#include <cstdint>

#include <tessera/format.h>
#include <tessera/stream.h>

namespace tessera::detail {

/// The view's footprint on the texture at one level: an axis-aligned box in level pixels
/// and, for perspective views, the level each part of it needs.
struct Footprint {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  ///< level-0 pixels, clipped to nothing
  double centre_x = 0, centre_y = 0;      ///< the point the clip regions centre on
  uint32_t desired_level = 0;             ///< the finest level any visible part needs
};

/// Computes the footprint of `view` over an image.
Footprint footprintOf(const View& view, const ImageInfo& info);

/// For perspective views: the level a tile needs (screen-space texel density at its nearest
/// point); for orthographic views the footprint's desired level.
uint32_t requiredLevelForTile(const View& view, const ImageInfo& info, const TileId& tile,
                              uint32_t desired_level);

}  // namespace tessera::detail
