#pragma once
// The compositor's arithmetic, shared by the fast compositor, the brute-force reference, the
// builder's analysis (coverage for culling, cost for the time filter) and the tests. Every
// function here is a pure function of integers prepared once per instance and tile level, so
// whichever loop calls it, the same texel gets the same bits (docs/procedural.md,
// "Determinism").

#include <array>
#include <cstdint>
#include <vector>

#include <tessera/procedural.h>

namespace tessera::detail {

/// Round-to-nearest x / 255 for 0 <= x <= 255 * 255 (exhaustively tested), every product of
/// two 8-bit values the compositor divides.
inline uint32_t div255(uint32_t x) {
  const uint32_t t = x + 128;
  return (t + (t >> 8)) >> 8;  // stays within 16 bits, so 16-bit lanes can compute it too
}

/// The bilinear filter of one 8-bit channel with 8-bit weights fx, fy (0..255), rounding after
/// each direction so that every intermediate fits 16 bits:
/// h = (a (256 - fx) + b fx + 128) >> 8 per row, then the same between the rows.
inline uint32_t bilinear(uint32_t t00, uint32_t t10, uint32_t t01, uint32_t t11, uint32_t fx,
                         uint32_t fy) {
  const uint32_t h0 = (t00 * (256 - fx) + t10 * fx + 128) >> 8;
  const uint32_t h1 = (t01 * (256 - fx) + t11 * fx + 128) >> 8;
  return (h0 * (256 - fy) + h1 * fy + 128) >> 8;
}

/// One level of a mip pyramid: RGBA (brush images) or gray (layers), rows packed.
struct MipLevel {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  std::vector<uint8_t> texels;
};

/// A brush image's pyramid: mips[0] is the image, each next one half the size (rounded up)
/// down to 1x1; alpha-weighted 2x2 means, colour bled into fully transparent texels so that
/// bilinear filtering of straight alpha shows no dark fringe.
struct ImagePyramid {
  std::vector<MipLevel> mips;
};

struct PreparedBrush {
  BlendMode blend = BlendMode::kNormal;
  MaskSource mask = MaskSource::kNone;
  std::array<uint8_t, 256> mask_lut{};  ///< layer value -> mask 0..255
  std::vector<ImagePyramid> images;
};

/// A gray layer's pyramid (height or slope): plain rounded 2x2 means.
struct LayerPyramid {
  std::vector<MipLevel> mips;
  bool empty() const { return mips.empty(); }
};

/// Everything a compositing tile needs about one instance at one level. Brush coordinates are
/// 16.16 fixed point in the chosen mip's texels, offset by -0.5 so that floor() is the
/// bilinear filter's first tap; they are affine in the level texel (X, Y):
/// u(X, Y) = u_c + du_dx (X - x_c) + du_dy (Y - y_c). Beyond `reach` texels of (x_c, y_c) in X
/// or Y the instance draws nothing, so no product ever leaves 64 bits.
struct InstanceSetup {
  const PreparedBrush* brush = nullptr;
  const MipLevel* mip = nullptr;
  int64_t x_c = 0, y_c = 0;  ///< level texel at the instance's centre
  int64_t reach = 0;         ///< texels from (x_c, y_c) beyond which nothing is drawn
  int64_t u_c = 0, v_c = 0;
  int64_t du_dx = 0, du_dy = 0, dv_dx = 0, dv_dy = 0;
  std::array<uint32_t, 4> tint{};  ///< per channel 0..255
  uint32_t opacity = 255;
  uint32_t mip_index = 0;
};

/// Prepares `instance` for tiles of `level`. Fails (kCorrupt, naming the instance) when the
/// brush is not in the set or a mask needs a layer the set lacks.
Result<InstanceSetup> setupInstance(const BrushSet::Impl& set, const BrushInstance& instance,
                                    uint32_t level);

/// The instance's source texel at level texel (X, Y), tinted, with opacity applied and before
/// any mask: writes rgba and returns its alpha (0: nothing drawn, rgba unspecified).
uint32_t sampleInstance(const InstanceSetup& setup, int64_t x, int64_t y, uint8_t rgba[4]);

/// Where the layer is read for level texel (X, Y) of `level`: the mip whose texel is nearest
/// the level's texel in size, the bilinear taps (edges clamped) and 8-bit weights. The column
/// taps depend on X alone and the row taps on Y alone (the GPU compositor uploads them per
/// column and row of a tile).
struct LayerTaps {
  uint32_t mip = 0;
  int64_t x0 = 0, x1 = 0, y0 = 0, y1 = 0;
  uint32_t fx = 0, fy = 0;
};
LayerTaps layerTaps(const LayerPyramid& layer, uint32_t texture_width_px,
                    uint32_t texture_height_px, uint32_t level, int64_t x, int64_t y);

/// The layer's value at level texel (X, Y) of `level`: bilinear in the mip whose texel is
/// nearest the level's texel in size, edges clamped.
uint8_t sampleLayer(const LayerPyramid& layer, uint32_t texture_width_px,
                    uint32_t texture_height_px, uint32_t level, int64_t x, int64_t y);

/// Blends source (s, alpha sa > 0) over the canvas texel `dst` (straight alpha, in place).
void blendTexel(BlendMode mode, const uint8_t s[4], uint32_t sa, uint8_t dst[4]);

/// The stored tile's texels whose level texel lies inside the level: [i0, i1) x [j0, j1). The
/// others (padding, borders past the image edge) repeat the nearest of these.
struct ValidRect {
  int64_t x0 = 0, y0 = 0;  ///< level texel of stored texel (0, 0), unclamped
  uint32_t i0 = 0, i1 = 0, j0 = 0, j1 = 0;
};
ValidRect validRect(const TileGeometry& tile);

/// The stored-tile texels [i_lo, i_hi) x [j_lo, j_hi) an instance may draw in a tile: the
/// valid rectangle, the instance's reach and its clip intersected. Empty when lo >= hi.
struct InstanceRect {
  int64_t i_lo = 0, i_hi = 0, j_lo = 0, j_hi = 0;
};
InstanceRect instanceRect(const InstanceSetup& setup, const ValidRect& rect, const TileClip& clip);

/// The level texel of a stored tile texel index, before clamping (docs/format.md, "Tiles").
inline int64_t levelTexel(uint32_t tile_index, uint32_t tile_size_px, uint32_t border_px,
                          uint32_t i) {
  return int64_t(tile_index) * tile_size_px - int64_t(border_px) + i;
}

}  // namespace tessera::detail

namespace tessera {

struct BrushSet::Impl {
  std::vector<Brush> brushes;  ///< as given (names, parameters, level-0 images)
  std::vector<detail::PreparedBrush> prepared;
  detail::LayerPyramid height;
  detail::LayerPyramid slope;
  uint32_t texture_width_px = 0;
  uint32_t texture_height_px = 0;
};

}  // namespace tessera
