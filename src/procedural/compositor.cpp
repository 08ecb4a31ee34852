// compositeTile and its brute-force reference (docs/procedural.md, "Compositing").
#include <tessera/procedural.h>

#include <algorithm>
#include <cstring>

#include "procedural/kernel.h"
#include "procedural/row_kernel.h"

namespace tessera::detail {

ValidRect validRect(const TileGeometry& tile) {
  const int64_t level_w = std::max<int64_t>(
      1, (int64_t(tile.image_width_px) + (int64_t(1) << tile.level) - 1) >> tile.level);
  const int64_t level_h = std::max<int64_t>(
      1, (int64_t(tile.image_height_px) + (int64_t(1) << tile.level) - 1) >> tile.level);
  ValidRect rect;
  rect.x0 = levelTexel(tile.x, tile.tile_size_px, tile.border_px, 0);
  rect.y0 = levelTexel(tile.y, tile.tile_size_px, tile.border_px, 0);
  const int64_t side = tile.sidePx();
  rect.i0 = uint32_t(std::clamp<int64_t>(-rect.x0, 0, side));
  rect.i1 = uint32_t(std::clamp<int64_t>(level_w - rect.x0, rect.i0, side));
  rect.j0 = uint32_t(std::clamp<int64_t>(-rect.y0, 0, side));
  rect.j1 = uint32_t(std::clamp<int64_t>(level_h - rect.y0, rect.j0, side));
  return rect;
}

InstanceRect instanceRect(const InstanceSetup& setup, const ValidRect& rect, const TileClip& clip) {
  // Only the texels within `reach` of the centre can be drawn (sampleInstance returns 0
  // beyond), so the loops visit those alone.
  InstanceRect r;
  r.i_lo = std::max<int64_t>({rect.i0, setup.x_c - setup.reach - rect.x0, clip.x0});
  r.i_hi = std::min<int64_t>({rect.i1, setup.x_c + setup.reach + 1 - rect.x0, clip.x1});
  r.j_lo = std::max<int64_t>({rect.j0, setup.y_c - setup.reach - rect.y0, clip.y0});
  r.j_hi = std::min<int64_t>({rect.j1, setup.y_c + setup.reach + 1 - rect.y0, clip.y1});
  return r;
}

}  // namespace tessera::detail

namespace tessera {

using namespace detail;

namespace {

// Copies the valid rectangle's edge texels outwards over the padding and outer borders.
void replicateEdges(const ValidRect& rect, uint32_t side, Image& out) {
  if (rect.i0 == rect.i1 || rect.j0 == rect.j1) return;
  const size_t row_bytes = size_t(side) * 4;
  for (uint32_t j = rect.j0; j < rect.j1; ++j) {
    uint8_t* row = out.texels.data() + j * row_bytes;
    for (uint32_t i = 0; i < rect.i0; ++i) std::memcpy(row + i * 4, row + rect.i0 * 4, 4);
    for (uint32_t i = rect.i1; i < side; ++i) std::memcpy(row + i * 4, row + (rect.i1 - 1) * 4, 4);
  }
  for (uint32_t j = 0; j < rect.j0; ++j)
    std::memcpy(out.texels.data() + j * row_bytes, out.texels.data() + rect.j0 * row_bytes,
                row_bytes);
  for (uint32_t j = rect.j1; j < side; ++j)
    std::memcpy(out.texels.data() + j * row_bytes, out.texels.data() + (rect.j1 - 1) * row_bytes,
                row_bytes);
}

void resetTile(uint32_t side, Image& out) {
  out.width_px = side;
  out.height_px = side;
  out.channels = 4;
  out.texels.assign(size_t(side) * side * 4, 0);
}

/// The tile's layer values over the valid rectangle, computed on first use.
class TileLayers {
 public:
  TileLayers(const BrushSet::Impl& set, const TileGeometry& tile, const ValidRect& rect)
      : set_(set), tile_(tile), rect_(rect) {}
  const uint8_t* values(MaskSource source) {
    std::vector<uint8_t>& cache = source == MaskSource::kHeight ? height_ : slope_;
    if (cache.empty()) {
      const LayerPyramid& layer = source == MaskSource::kHeight ? set_.height : set_.slope;
      const uint32_t w = rect_.i1 - rect_.i0;
      cache.resize(size_t(w) * (rect_.j1 - rect_.j0));
      for (uint32_t j = rect_.j0; j < rect_.j1; ++j)
        for (uint32_t i = rect_.i0; i < rect_.i1; ++i)
          cache[size_t(j - rect_.j0) * w + (i - rect_.i0)] =
              sampleLayer(layer, set_.texture_width_px, set_.texture_height_px, tile_.level,
                          rect_.x0 + i, rect_.y0 + j);
    }
    return cache.data();
  }

 private:
  const BrushSet::Impl& set_;
  const TileGeometry& tile_;
  const ValidRect& rect_;
  std::vector<uint8_t> height_, slope_;
};

}  // namespace

BoxPx tileQueryBox(const TileGeometry& tile) {
  const double level_px = double(int64_t(1) << tile.level);
  const double x0 = double(levelTexel(tile.x, tile.tile_size_px, tile.border_px, 0));
  const double y0 = double(levelTexel(tile.y, tile.tile_size_px, tile.border_px, 0));
  const double side = tile.sidePx();
  // Three texels of the level on every side. An instance draws level texels x with
  // |x - x_c| <= reach, x_c = floor(X / L), reach = floor(E / L) + 2 (setupInstance), E its
  // bounds' half side: so from (X - E) / L - 3 to (X + E) / L + 2 in level texels. A box grown
  // by one texel (a bilinear footprint) missed a large instance's fringe at coarse levels,
  // where the fringe of its magnified brush image passes the bounds' corner.
  return {(x0 - 3) * level_px, (y0 - 3) * level_px, (x0 + side + 3) * level_px,
          (y0 + side + 3) * level_px};
}

Result<void> compositeTile(const BrushSet& brushes, const TileGeometry& tile,
                           std::span<const BrushInstance> instances, Image& out,
                           std::span<const TileClip> clips) {
  TESSERA_CHECK(clips.empty() || clips.size() == instances.size()) << "one clip per instance";
  const BrushSet::Impl& set = brushes.impl();
  const uint32_t side = tile.sidePx();
  resetTile(side, out);
  const ValidRect rect = validRect(tile);
  TileLayers layers(set, tile, rect);
  const uint32_t layer_w = rect.i1 - rect.i0;
  for (size_t n = 0; n < instances.size(); ++n) {
    const BrushInstance& instance = instances[n];
    const TileClip clip = clips.empty() ? TileClip{} : clips[n];
    TESSERA_ASSIGN_OR_RETURN(InstanceSetup setup, setupInstance(set, instance, tile.level));
    const auto [i_lo, i_hi, j_lo, j_hi] = instanceRect(setup, rect, clip);
    if (i_lo >= i_hi || j_lo >= j_hi) continue;
    const uint8_t* mask_values =
        setup.brush->mask == MaskSource::kNone ? nullptr : layers.values(setup.brush->mask);
    for (int64_t j = j_lo; j < j_hi; ++j) {
      const int64_t y = rect.y0 + j;
      const RowSpan span = instanceRowSpan(setup, y);
      const int64_t first = std::max(span.first, rect.x0 + i_lo);
      const int64_t last = std::min(span.last, rect.x0 + i_hi - 1);
      if (first > last) continue;
      const int64_t i = first - rect.x0;
      drawInstanceRow(
          setup, y, first, last,
          mask_values ? mask_values + size_t(j - rect.j0) * layer_w + size_t(i - rect.i0) : nullptr,
          out.texels.data() + (size_t(j) * side + size_t(i)) * 4);
    }
  }
  replicateEdges(rect, side, out);
  return {};
}

Result<void> compositeTileReference(const BrushSet& brushes, const TileGeometry& tile,
                                    std::span<const BrushInstance> instances, Image& out) {
  const BrushSet::Impl& set = brushes.impl();
  const uint32_t side = tile.sidePx();
  resetTile(side, out);
  const int64_t level_w = std::max<int64_t>(
      1, (int64_t(tile.image_width_px) + (int64_t(1) << tile.level) - 1) >> tile.level);
  const int64_t level_h = std::max<int64_t>(
      1, (int64_t(tile.image_height_px) + (int64_t(1) << tile.level) - 1) >> tile.level);
  for (const BrushInstance& instance : instances) {
    TESSERA_ASSIGN_OR_RETURN(InstanceSetup setup, setupInstance(set, instance, tile.level));
    for (uint32_t j = 0; j < side; ++j) {
      const int64_t y = std::clamp<int64_t>(
          levelTexel(tile.y, tile.tile_size_px, tile.border_px, j), 0, level_h - 1);
      for (uint32_t i = 0; i < side; ++i) {
        const int64_t x = std::clamp<int64_t>(
            levelTexel(tile.x, tile.tile_size_px, tile.border_px, i), 0, level_w - 1);
        uint8_t source[4];
        uint32_t alpha = sampleInstance(setup, x, y, source);
        if (alpha == 0) continue;
        if (setup.brush->mask != MaskSource::kNone) {
          const LayerPyramid& layer =
              setup.brush->mask == MaskSource::kHeight ? set.height : set.slope;
          alpha = div255(
              alpha * setup.brush->mask_lut[sampleLayer(layer, set.texture_width_px,
                                                        set.texture_height_px, tile.level, x, y)]);
          if (alpha == 0) continue;
        }
        blendTexel(setup.brush->blend, source, alpha,
                   out.texels.data() + (size_t(j) * side + i) * 4);
      }
    }
  }
  return {};
}

}  // namespace tessera
