#pragma once
// An independent, deliberately plain in-memory model of what the builder must produce: the
// whole pyramid held in memory, every level computed texel by texel from the rules in
// docs/format.md ("Levels", "Tiles"), and tiles cut by clamping coordinates. It shares no code
// with src/build, so the streaming builder is checked against a second reading of the spec.

#include <cstdint>
#include <string>
#include <vector>

#include <tessera/format.h>

namespace tessera::test {

/// The tile kind the rules predict, and for uniform tiles the colour.
struct ReferenceTile {
  Image texels;  ///< (tile + 2 border)^2, the image's channels
  TileKind kind = TileKind::kEncoded;
  uint32_t uniform_rgba = 0;  ///< channel c in byte c, when kind is kUniform
};

/// Every level of an image, level 0 first.
class ReferencePyramid {
 public:
  /// Builds every level from `level0` down to 1 x 1, with referenceDownsample or, when
  /// `floor_average`, referenceFloorDownsample (the ptm codec's pyramid).
  explicit ReferencePyramid(Image level0, bool floor_average = false);

  /// Levels an archive with `tile_size_px` tiles holds: up to the first that fits one tile.
  uint32_t levelCount(uint32_t tile_size_px) const;
  const Image& level(uint32_t level) const { return levels_[level]; }
  uint32_t tilesX(uint32_t level, uint32_t tile_size_px) const;
  uint32_t tilesY(uint32_t level, uint32_t tile_size_px) const;

  /// Tile (x, y) of `level` with side t = `tile_size_px` and `border_px` border texels: texel
  /// (sx, sy) is the level's texel at (x * t - b + sx, y * t - b + sy) clamped into the level.
  ReferenceTile tile(uint32_t level, uint32_t x, uint32_t y, uint32_t tile_size_px,
                     uint32_t border_px) const;

  /// `rect` of `level` in the image's channels; texels outside the level are zero.
  Image region(uint32_t level, int64_t x, int64_t y, uint32_t width, uint32_t height) const;

 private:
  std::vector<Image> levels_;
};

/// One 2x2 box-filter step: ceil(w/2) x ceil(h/2), odd edges averaged with themselves,
/// (sum + 2) >> 2 per channel; with alpha (2 or 4 channels) colour weighted by alpha,
/// (sum c*a + A/2) / A, alpha (A + 2) >> 2, and a fully transparent block all zero.
Image referenceDownsample(const Image& level);

/// The integer pyramid step of Marvie & Bouatouch (eq. 1 and 3): floor(sum / 4) per channel,
/// alpha unweighted, odd edges averaged with themselves.
Image referenceFloorDownsample(const Image& level);

/// Test pixels with the features kinds depend on: a flat opaque block (uniform tiles), with
/// alpha an all-zero block (empty tiles) and scattered transparent and translucent texels
/// (alpha weighting), and noise elsewhere. Deterministic in `seed`.
Image makePatternImage(uint32_t width_px, uint32_t height_px, uint32_t channels, uint32_t seed);

/// Describes the first differing texel of two images ("" when equal), for failure messages.
std::string firstDifference(const Image& expected, const Image& actual);

}  // namespace tessera::test
