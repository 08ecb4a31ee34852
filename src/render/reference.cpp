// The CPU reference renderer: every pixel by the sampling rules of docs/rendering.md, straight
// from the archive's tiles. Slow next to a GPU, but with no state beyond one call, it is the
// ground truth the GPU renderers and `tessera fly` compare against.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include <fmt/format.h>

#include <tessera/render.h>

#include "view/screen_mapping.h"

namespace tessera {

namespace {

/// One tile of the image as the renderer met it. `rgba` holds the tile's t x t texels
/// (borders dropped) expanded to RGBA, filled on first sampling.
struct TileSlot {
  bool available = false;
  bool decoded = false;
  std::vector<uint8_t> rgba;
};

/// The last tile a level's lookups hit: neighbouring pixels sample the same tile, so most
/// lookups skip the hash map.
struct TileCursor {
  int64_t tile_x = -1;
  int64_t tile_y = -1;
  TileSlot* slot = nullptr;
};

/// A level's geometry and cursors.
struct LevelState {
  uint32_t width_px = 0;  ///< the level's image, ceil(W / 2^level)
  uint32_t height_px = 0;
  double scale = 1;  ///< 2^-level: level-0 texels to this level's texels
  TileCursor texel_cursor;
  TileCursor available_cursor;
};

/// Draws one picture. Owned by one thread; lives for one renderReference call.
class ReferenceRenderer {
 public:
  ReferenceRenderer(const Archive& archive, const ImageInfo& info, uint32_t image,
                    const ReferenceOptions& options)
      : archive_(archive), info_(info), image_(image), options_(options) {
    tile_shift_ = uint32_t(std::countr_zero(info.tile_size_px));
    levels_.resize(info.level_count);
    for (uint32_t level = 0; level < info.level_count; ++level) {
      levels_[level].width_px = info.levelWidthPx(level);
      levels_[level].height_px = info.levelHeightPx(level);
      levels_[level].scale = std::ldexp(1.0, -int(level));
    }
  }

  Result<Picture> render(const View& view) {
    Picture picture;
    picture.width = view.viewportWidth();
    picture.height = view.viewportHeight();
    picture.rgba.assign(size_t(picture.width) * picture.height * 4, 0);
    const detail::ScreenMapping mapping(view);
    const double image_w = info_.width_px, image_h = info_.height_px;
    const uint32_t coarsest = info_.level_count - 1;
    detail::TexelPoint point;
    for (uint32_t py = 0; py < picture.height; ++py) {
      uint8_t* out = picture.rgba.data() + size_t(py) * picture.width * 4;
      for (uint32_t px = 0; px < picture.width; ++px, out += 4) {
        if (!mapping.map(px + 0.5, py + 0.5, point)) continue;
        if (!(point.u >= 0 && point.u < image_w && point.v >= 0 && point.v < image_h)) continue;
        const double lambda = point.lambda;
        const uint32_t level = wantedLevel(lambda);
        const int32_t shown_or_none = shownLevel(point);
        if (shown_or_none < 0) continue;  // nothing resident covers it: transparent
        const uint32_t shown = uint32_t(shown_or_none);
        double colour[4];
        if (!bilinear(shown, point.u, point.v, colour)) return Unexpected(std::move(error_));
        const double blend =
            shown == level && level < coarsest ? std::clamp(lambda - level, 0.0, 1.0) : 0;
        if (blend > 0) {
          // Trilinear: the next level is sampled whether or not its tiles are "available";
          // a GPU renderer samples the resident parent, and the streamer keeps the parents of
          // resident tiles resident (docs/rendering.md, "The fallback").
          double coarser[4];
          if (!bilinear(level + 1, point.u, point.v, coarser)) return Unexpected(std::move(error_));
          for (int c = 0; c < 4; ++c) colour[c] = (1 - blend) * colour[c] + blend * coarser[c];
        }
        for (int c = 0; c < 4; ++c)
          out[c] = uint8_t(std::clamp(std::floor(colour[c] + 0.5), 0.0, 255.0));
      }
    }
    return picture;
  }

  /// The level each pixel shows, row-major; -1 outside the image or where nothing is
  /// available.
  std::vector<int32_t> levels(const View& view) {
    const uint32_t width = view.viewportWidth(), height = view.viewportHeight();
    std::vector<int32_t> out(size_t(width) * height, -1);
    const detail::ScreenMapping mapping(view);
    detail::TexelPoint point;
    for (uint32_t py = 0; py < height; ++py)
      for (uint32_t px = 0; px < width; ++px)
        if (mapping.map(px + 0.5, py + 0.5, point) && point.u >= 0 && point.u < info_.width_px &&
            point.v >= 0 && point.v < info_.height_px)
          out[size_t(py) * width + px] = shownLevel(point);
    return out;
  }

 private:
  /// L = floor(lambda) clamped to the levels; below 0 is magnification of level 0.
  uint32_t wantedLevel(double lambda) const {
    const uint32_t coarsest = info_.level_count - 1;
    return lambda >= 1 ? uint32_t(std::min(std::floor(lambda), double(coarsest))) : 0;
  }

  /// The finest available level at or above the wanted one at a point of the image, or -1.
  int32_t shownLevel(const detail::TexelPoint& point) {
    uint32_t shown = wantedLevel(point.lambda);
    if (options_.available)
      while (shown < info_.level_count && !isAvailable(shown, point.u, point.v)) ++shown;
    return shown < info_.level_count ? int32_t(shown) : -1;
  }

  static uint64_t keyOf(uint32_t level, int64_t tile_x, int64_t tile_y) {
    return uint64_t(level) << 58 | uint64_t(tile_x) << 29 | uint64_t(tile_y);
  }

  /// The slot of a tile, asking `available` on first sight.
  TileSlot& slotOf(uint32_t level, int64_t tile_x, int64_t tile_y) {
    auto [it, inserted] = slots_.try_emplace(keyOf(level, tile_x, tile_y));
    if (inserted)
      it->second.available =
          !options_.available ||
          options_.available(TileId{image_, level, uint32_t(tile_x), uint32_t(tile_y)});
    return it->second;
  }

  /// Whether the tile of `level` holding level-0 point (u, v), which lies in the image, is
  /// available.
  bool isAvailable(uint32_t level, double u, double v) {
    LevelState& state = levels_[level];
    const int64_t tile_x = int64_t(u * state.scale) >> tile_shift_;
    const int64_t tile_y = int64_t(v * state.scale) >> tile_shift_;
    TileCursor& cursor = state.available_cursor;
    if (cursor.tile_x != tile_x || cursor.tile_y != tile_y)
      cursor = {tile_x, tile_y, &slotOf(level, tile_x, tile_y)};
    return cursor.slot->available;
  }

  /// RGBA of texel (x, y) of `level`, inside the level's image; null on a read or decode
  /// failure, with `error_` set.
  const uint8_t* texel(uint32_t level, uint32_t x, uint32_t y) {
    LevelState& state = levels_[level];
    const int64_t tile_x = x >> tile_shift_, tile_y = y >> tile_shift_;
    TileCursor& cursor = state.texel_cursor;
    if (cursor.tile_x != tile_x || cursor.tile_y != tile_y) {
      TileSlot& slot = slotOf(level, tile_x, tile_y);
      if (!slot.decoded && !decode(TileId{image_, level, uint32_t(tile_x), uint32_t(tile_y)}, slot))
        return nullptr;
      cursor = {tile_x, tile_y, &slot};
    }
    const uint32_t mask = info_.tile_size_px - 1;
    return cursor.slot->rgba.data() + ((size_t(y & mask) << tile_shift_) + (x & mask)) * 4;
  }

  /// Reads and decodes a tile into `slot`, expanding its channels to RGBA as a renderer shows
  /// them: grey (g, g, g, 255), grey+alpha (g, g, g, a), RGB with alpha 255.
  bool decode(const TileId& id, TileSlot& slot) {
    Result<Image> tile = archive_.readTile(id);
    if (!tile) {
      error_ = tile.error();
      // Byte sources name the file and offset, not the tile: say which tile was wanted.
      const std::string tag = fmt::format("tile ({},{},{})", id.level, id.x, id.y);
      if (error_.message.find(tag) == std::string::npos)
        error_.message = fmt::format("{}: {}: {}", archive_.name(), tag, error_.message);
      return false;
    }
    const uint32_t t = info_.tile_size_px, border = info_.border_px, channels = info_.channels;
    slot.rgba.resize(size_t(t) * t * 4);
    uint8_t* out = slot.rgba.data();
    for (uint32_t y = 0; y < t; ++y) {
      const uint8_t* in = tile->row(y + border) + size_t(border) * channels;
      for (uint32_t x = 0; x < t; ++x, in += channels, out += 4) {
        switch (channels) {
          case 1: out[0] = out[1] = out[2] = in[0], out[3] = 255; break;
          case 2: out[0] = out[1] = out[2] = in[0], out[3] = in[1]; break;
          case 3: out[0] = in[0], out[1] = in[1], out[2] = in[2], out[3] = 255; break;
          default: std::memcpy(out, in, 4); break;
        }
      }
    }
    slot.decoded = true;
    return true;
  }

  /// Bilinear sample of `level` at level-0 point (u, v): the four texels around
  /// (u, v) / 2^level - 0.5, indices clamped to the level's image. False on a tile failure.
  bool bilinear(uint32_t level, double u, double v, double colour[4]) {
    const LevelState& state = levels_[level];
    const double x = u * state.scale - 0.5, y = v * state.scale - 0.5;
    const double x_floor = std::floor(x), y_floor = std::floor(y);
    const double fx = x - x_floor, fy = y - y_floor;
    const int64_t x0 = int64_t(x_floor), y0 = int64_t(y_floor);
    const int64_t last_x = int64_t(state.width_px) - 1, last_y = int64_t(state.height_px) - 1;
    const uint32_t xa = uint32_t(std::clamp<int64_t>(x0, 0, last_x));
    const uint32_t xb = uint32_t(std::clamp<int64_t>(x0 + 1, 0, last_x));
    const uint32_t ya = uint32_t(std::clamp<int64_t>(y0, 0, last_y));
    const uint32_t yb = uint32_t(std::clamp<int64_t>(y0 + 1, 0, last_y));
    const uint8_t* t00 = texel(level, xa, ya);
    if (!t00) return false;
    const uint8_t* t10 = texel(level, xb, ya);
    if (!t10) return false;
    const uint8_t* t01 = texel(level, xa, yb);
    if (!t01) return false;
    const uint8_t* t11 = texel(level, xb, yb);
    if (!t11) return false;
    const double w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
    for (int c = 0; c < 4; ++c)
      colour[c] = w00 * t00[c] + w10 * t10[c] + w01 * t01[c] + w11 * t11[c];
    return true;
  }

  const Archive& archive_;
  const ImageInfo& info_;
  uint32_t image_;
  const ReferenceOptions& options_;
  uint32_t tile_shift_ = 0;  ///< log2(tile_size_px)
  std::vector<LevelState> levels_;
  /// Every tile met this call, by level and position; node-based, so cursors stay valid.
  std::unordered_map<uint64_t, TileSlot> slots_;
  Error error_;  ///< why the last texel() returned null
};

}  // namespace

Result<Picture> renderReference(const Archive& archive, const View& view,
                                const ReferenceOptions& options) {
  if (view.image >= archive.images().size())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: no image {} (archive has {})", archive.name(), view.image,
                            archive.images().size()));
  const ImageInfo& info = archive.images()[view.image];
  // Its texel cache holds 8-bit RGBA; a wide image would need the display window there too.
  if (info.sample_type != SampleType::kU8)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: image {} has {} samples; the reference renderer draws 8-bit "
                            "images only",
                            archive.name(), view.image, sampleTypeName(info.sample_type)));
  ReferenceRenderer renderer(archive, info, view.image, options);
  return renderer.render(view);
}

Result<std::vector<int32_t>> levelsShown(const Archive& archive, const View& view,
                                         const ReferenceOptions& options) {
  if (view.image >= archive.images().size())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: no image {} (archive has {})", archive.name(), view.image,
                            archive.images().size()));
  ReferenceRenderer renderer(archive, archive.images()[view.image], view.image, options);
  return renderer.levels(view);
}

}  // namespace tessera
