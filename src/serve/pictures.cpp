#include "serve/pictures.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <span>

#include <fmt/format.h>

#include "codecs/encode.h"

namespace tessera::detail {

namespace {

uint32_t ceilLog2(uint64_t value) {
  return value <= 1 ? 0 : uint32_t(std::bit_width(value - 1));
}

uint32_t scaledSide(uint32_t side_px, uint32_t scale_log2) {
  if (scale_log2 >= 32) return 1;
  uint64_t scale = uint64_t(1) << scale_log2;
  return uint32_t(std::max<uint64_t>(1, (side_px + scale - 1) / scale));
}

Image crop(const Image& source, uint32_t x, uint32_t y, uint32_t width, uint32_t height) {
  Image out(width, height, source.channels);
  for (uint32_t row = 0; row < height; ++row)
    std::memcpy(out.row(row), source.row(y + row) + size_t(x) * source.channels, out.strideBytes());
  return out;
}

// Box filter over 2^k x 2^k blocks (partial at the right and bottom edges), which is what
// k halvings of the archive's own 2x2 averaging approximate.
Image boxDownsample(const Image& source, uint32_t k, uint32_t width, uint32_t height) {
  Image out(width, height, source.channels);
  const uint32_t factor = 1u << k;
  for (uint32_t y = 0; y < height; ++y) {
    const uint32_t y0 = y * factor, y1 = std::min(source.height_px, y0 + factor);
    for (uint32_t x = 0; x < width; ++x) {
      const uint32_t x0 = x * factor, x1 = std::min(source.width_px, x0 + factor);
      for (uint32_t c = 0; c < source.channels; ++c) {
        uint64_t sum = 0;
        for (uint32_t sy = y0; sy < y1; ++sy)
          for (uint32_t sx = x0; sx < x1; ++sx) sum += source.row(sy)[sx * source.channels + c];
        const uint64_t count = uint64_t(y1 - y0) * (x1 - x0);
        out.row(y)[x * source.channels + c] = uint8_t((sum + count / 2) / count);
      }
    }
  }
  return out;
}

// Texels of a u16 or f32 image mapped to RGBA8 by the request's window; u8 texels as they are.
Image eightBit(Image texels, const DisplayWindow& window) {
  if (texels.sample_type == SampleType::kU8) return texels;
  return windowToRgba8(texels, window);
}

// `rect` (inside the scaled image) of the image scaled down by 2^scale_log2: a region of that
// archive level, or of the coarsest level box-filtered further (wide images windowed first,
// so the filter averages 8-bit codes there).
Result<Image> readScaled(const Archive& archive, uint32_t image, uint32_t scale_log2,
                         const PixelRect& rect, const DisplayWindow& window) {
  const ImageInfo& info = archive.images()[image];
  if (scale_log2 < info.level_count) {
    TESSERA_ASSIGN_OR_RETURN(Image region, archive.readRegion(image, scale_log2, rect));
    return eightBit(std::move(region), window);
  }
  const uint32_t coarsest = info.level_count - 1;
  TESSERA_ASSIGN_OR_RETURN(Image level, archive.readRegion(image, coarsest,
                                                           {0, 0, info.levelWidthPx(coarsest),
                                                            info.levelHeightPx(coarsest)}));
  const Image whole = eightBit(std::move(level), window);
  Image scaled = boxDownsample(whole, scale_log2 - coarsest, scaledSide(info.width_px, scale_log2),
                               scaledSide(info.height_px, scale_log2));
  return crop(scaled, uint32_t(rect.x), uint32_t(rect.y), rect.width, rect.height);
}

// JPEG has no alpha: keep the colour (or gray) channels.
Image withoutAlpha(const Image& source) {
  if (source.channels == 1 || source.channels == 3) return source;
  Image out(source.width_px, source.height_px, source.channels - 1);
  const size_t texels = size_t(source.width_px) * source.height_px;
  for (size_t i = 0; i < texels; ++i)
    std::memcpy(&out.texels[i * out.channels], &source.texels[i * source.channels], out.channels);
  return out;
}

Result<Picture> encode(const Image& picture, PictureFormat format, int jpeg_quality) {
  EncodeOptions options;
  options.quality = jpeg_quality;
  Result<std::vector<uint8_t>> bytes =
      format == PictureFormat::kPng
          ? encodeTile(Codec::kPng, picture.view(), options)
          : encodeTile(Codec::kJpeg, withoutAlpha(picture).view(), options);
  if (!bytes) return forwardError(bytes);
  return Picture{std::string(bytes->begin(), bytes->end())};
}

// An XYZ tile is RGBA whatever the image: gray is spread to the colour channels, and alpha is
// opaque where the image has none.
void toRgba8(const uint8_t* texel, uint32_t channels, uint8_t* out) {
  const bool gray = channels <= 2;
  out[0] = texel[0];
  out[1] = gray ? texel[0] : texel[1];
  out[2] = gray ? texel[0] : texel[2];
  out[3] = channels == 2 ? texel[1] : channels == 4 ? texel[3] : 255;
}

// A picture of one colour: the first texel written, then doubled by copies of what is filled.
Image filled(uint32_t width, uint32_t height, uint32_t channels, const uint8_t* texel) {
  Image out(width, height, channels);
  std::span<uint8_t> texels(out.texels);
  size_t done = std::min<size_t>(channels, texels.size());
  std::memcpy(texels.data(), texel, done);
  while (done < texels.size()) {
    const size_t copy = std::min(done, texels.size() - done);
    std::memcpy(texels.data() + done, texels.data(), copy);
    done += copy;
  }
  return out;
}

// Deep Zoom tile (col, row) of the level scaled by 2^scale, inside that level's grid: overlap
// is added on the sides that have a neighbour (the Deep Zoom convention).
PixelRect dziTileRect(const ImageInfo& info, uint32_t scale, uint32_t col, uint32_t row) {
  const uint32_t width = scaledWidthPx(info, scale), height = scaledHeightPx(info, scale);
  const uint32_t tile = info.tile_size_px, overlap = dziOverlap(info);
  const uint64_t x0 = uint64_t(col) * tile - (col > 0 ? overlap : 0);
  const uint64_t y0 = uint64_t(row) * tile - (row > 0 ? overlap : 0);
  const uint64_t x1 = std::min<uint64_t>(uint64_t(col + 1) * tile + overlap, width);
  const uint64_t y1 = std::min<uint64_t>(uint64_t(row + 1) * tile + overlap, height);
  return {int64_t(x0), int64_t(y0), uint32_t(x1 - x0), uint32_t(y1 - y0)};
}

Result<void> checkImage(const Archive& archive, uint32_t image) {
  if (image >= archive.images().size())
    return fail(ErrorCode::kNotFound, fmt::format("{}: no image {}", archive.name(), image));
  return {};
}

}  // namespace

std::optional<PictureFormat> parsePictureFormat(std::string_view text) {
  if (text == "png") return PictureFormat::kPng;
  if (text == "jpg" || text == "jpeg") return PictureFormat::kJpeg;
  return std::nullopt;
}

const char* pictureContentType(PictureFormat format) {
  return format == PictureFormat::kPng ? "image/png" : "image/jpeg";
}

uint32_t dziMaxLevel(const ImageInfo& info) {
  return ceilLog2(std::max(info.width_px, info.height_px));
}

PictureFormat dziFormat(const ImageInfo& info) {
  const bool alpha = info.channels == 2 || info.channels == 4;
  return info.default_codec == Codec::kJpeg && !alpha ? PictureFormat::kJpeg : PictureFormat::kPng;
}

const char* dziExtension(PictureFormat format) {
  return format == PictureFormat::kPng ? "png" : "jpg";
}

bool browserReady(const ImageInfo& info, Codec codec, PictureFormat format) {
  if (format == PictureFormat::kJpeg)
    return codec == Codec::kJpeg && (info.channels == 1 || info.channels == 3);
  return codec == Codec::kPng;
}

std::string dziDescriptor(const ImageInfo& info) {
  return fmt::format(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<Image xmlns=\"http://schemas.microsoft.com/deepzoom/2008\" TileSize=\"{}\" "
      "Overlap=\"{}\" Format=\"{}\">\n  <Size Width=\"{}\" Height=\"{}\"/>\n</Image>\n",
      info.tile_size_px, dziOverlap(info), dziExtension(dziFormat(info)), info.width_px,
      info.height_px);
}

uint32_t xyzMaxZoom(const ImageInfo& info) {
  const uint32_t side = std::max(info.width_px, info.height_px);
  return ceilLog2((side + kXyzTileSizePx - 1) / kXyzTileSizePx);
}

uint32_t scaledWidthPx(const ImageInfo& info, uint32_t scale_log2) {
  return scaledSide(info.width_px, scale_log2);
}

uint32_t scaledHeightPx(const ImageInfo& info, uint32_t scale_log2) {
  return scaledSide(info.height_px, scale_log2);
}

Result<Picture> renderDziTile(const Archive& archive, uint32_t image, uint32_t dz_level,
                              uint32_t col, uint32_t row, PictureFormat format, int jpeg_quality,
                              const DisplayWindow& window) {
  TESSERA_TRY(checkImage(archive, image));
  const ImageInfo& info = archive.images()[image];
  const uint32_t max_level = dziMaxLevel(info);
  if (dz_level > max_level)
    return fail(ErrorCode::kNotFound, fmt::format("{}: no Deep Zoom level {} (finest is {})",
                                                  archive.name(), dz_level, max_level));
  const uint32_t scale = max_level - dz_level;
  const uint32_t width = scaledWidthPx(info, scale), height = scaledHeightPx(info, scale);
  const uint32_t tile = info.tile_size_px, overlap = dziOverlap(info);
  const uint32_t cols = (width + tile - 1) / tile, rows = (height + tile - 1) / tile;
  if (col >= cols || row >= rows)
    return fail(ErrorCode::kNotFound,
                fmt::format("{}: Deep Zoom tile {}/{}_{} is outside the level's {}x{} tiles",
                            archive.name(), dz_level, col, row, cols, rows));
  const PixelRect rect = dziTileRect(info, scale, col, row);
  const uint64_t x0 = uint64_t(rect.x), y0 = uint64_t(rect.y);

  if (scale < info.level_count) {
    // One stored tile holds the whole DZI tile: its border is the overlap.
    const TileId id{image, scale, col, row};
    TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(id));
    const bool whole_stored_tile = overlap == 0 && rect.width == tile && rect.height == tile;
    if (whole_stored_tile && entry.kind == TileKind::kEncoded &&
        browserReady(info, entry.codec, format)) {
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload, archive.readPayload(id, entry));
      return Picture{std::string(payload.begin(), payload.end()), true};
    }
    std::vector<uint8_t> payload;
    if (entry.hasPayload()) {
      TESSERA_ASSIGN_OR_RETURN(payload, archive.readPayload(id, entry));
    }
    TESSERA_ASSIGN_OR_RETURN(Image decoded, archive.decodeTile(id, entry, payload));
    const Image stored = eightBit(std::move(decoded), window);
    const uint64_t origin_x = uint64_t(col) * tile - info.border_px;
    const uint64_t origin_y = uint64_t(row) * tile - info.border_px;
    // Unsigned wrap-around cancels: x0 >= col * tile - border whenever overlap == border.
    return encode(
        crop(stored, uint32_t(x0 - origin_x), uint32_t(y0 - origin_y), rect.width, rect.height),
        format, jpeg_quality);
  }
  TESSERA_ASSIGN_OR_RETURN(Image region, readScaled(archive, image, scale, rect, window));
  return encode(region, format, jpeg_quality);
}

Result<Picture> renderXyzTile(const Archive& archive, uint32_t image, uint32_t z, uint32_t x,
                              uint32_t y, PictureFormat format, int jpeg_quality,
                              const DisplayWindow& window) {
  TESSERA_TRY(checkImage(archive, image));
  const ImageInfo& info = archive.images()[image];
  const uint32_t max_zoom = xyzMaxZoom(info);
  if (z > max_zoom)
    return fail(ErrorCode::kNotFound,
                fmt::format("{}: no XYZ zoom {} (deepest is {})", archive.name(), z, max_zoom));
  const uint32_t scale = max_zoom - z;
  const uint32_t width = scaledWidthPx(info, scale), height = scaledHeightPx(info, scale);
  const uint64_t x0 = uint64_t(x) * kXyzTileSizePx, y0 = uint64_t(y) * kXyzTileSizePx;
  if (x0 >= width || y0 >= height)
    return fail(ErrorCode::kNotFound,
                fmt::format("{}: XYZ tile {}/{}/{} is outside the {}x{} px image at that zoom",
                            archive.name(), z, x, y, width, height));
  const uint32_t inside_w = uint32_t(std::min<uint64_t>(kXyzTileSizePx, width - x0));
  const uint32_t inside_h = uint32_t(std::min<uint64_t>(kXyzTileSizePx, height - y0));

  if (const std::optional<TileId> id = xyzStoredTile(info, image, z, x, y)) {
    TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(*id));
    if (entry.kind == TileKind::kEncoded && browserReady(info, entry.codec, format)) {
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload, archive.readPayload(*id, entry));
      return Picture{std::string(payload.begin(), payload.end()), true};
    }
  }
  TESSERA_ASSIGN_OR_RETURN(
      Image region,
      readScaled(archive, image, scale, {int64_t(x0), int64_t(y0), inside_w, inside_h}, window));
  // Leaflet expects whole tiles: paste into a transparent 256 x 256 RGBA tile.
  Image tile(kXyzTileSizePx, kXyzTileSizePx, 4);
  for (uint32_t row = 0; row < inside_h; ++row) {
    const uint8_t* src = region.row(row);
    uint8_t* dst = tile.row(row);
    for (uint32_t col = 0; col < inside_w; ++col)
      toRgba8(src + size_t(col) * region.channels, region.channels, dst + size_t(col) * 4);
  }
  return encode(tile, format, jpeg_quality);
}

std::optional<TileId> xyzStoredTile(const ImageInfo& info, uint32_t image, uint32_t z, uint32_t x,
                                    uint32_t y) {
  const uint32_t max_zoom = xyzMaxZoom(info);
  if (z > max_zoom) return std::nullopt;
  const uint32_t scale = max_zoom - z;
  if (scale >= info.level_count || info.tile_size_px != kXyzTileSizePx || info.border_px != 0)
    return std::nullopt;
  const uint64_t x1 = (uint64_t(x) + 1) * kXyzTileSizePx, y1 = (uint64_t(y) + 1) * kXyzTileSizePx;
  if (x1 > scaledWidthPx(info, scale) || y1 > scaledHeightPx(info, scale)) return std::nullopt;
  return TileId{image, scale, x, y};
}

std::optional<UniformTexel> uniformTexel(const ImageInfo& info, const TileEntry& entry) {
  if (info.sample_type != SampleType::kU8) return std::nullopt;
  if (entry.kind == TileKind::kEmpty) return UniformTexel{0};
  if (entry.kind == TileKind::kUniform) return UniformTexel{entry.uniform_rgba};
  return std::nullopt;
}

Result<Picture> uniformXyzPicture(const ImageInfo& info, UniformTexel texel, PictureFormat format,
                                  int jpeg_quality) {
  uint8_t stored[4], rgba[4];
  for (uint32_t c = 0; c < 4; ++c) stored[c] = uint8_t(texel.rgba >> (8 * c));
  toRgba8(stored, info.channels, rgba);
  return encode(filled(kXyzTileSizePx, kXyzTileSizePx, 4, rgba), format, jpeg_quality);
}

std::optional<DziStoredTile> dziStoredTile(const ImageInfo& info, uint32_t image, uint32_t dz_level,
                                           uint32_t col, uint32_t row) {
  const uint32_t max_level = dziMaxLevel(info);
  if (dz_level > max_level || max_level - dz_level >= info.level_count) return std::nullopt;
  const uint32_t scale = max_level - dz_level, tile = info.tile_size_px;
  if (uint64_t(col) * tile >= scaledWidthPx(info, scale) ||
      uint64_t(row) * tile >= scaledHeightPx(info, scale))
    return std::nullopt;
  const PixelRect rect = dziTileRect(info, scale, col, row);
  return DziStoredTile{{image, scale, col, row}, rect.width, rect.height};
}

Result<Picture> uniformDziPicture(const ImageInfo& info, UniformTexel texel, uint32_t width_px,
                                  uint32_t height_px, PictureFormat format, int jpeg_quality) {
  uint8_t stored[4];
  for (uint32_t c = 0; c < 4; ++c) stored[c] = uint8_t(texel.rgba >> (8 * c));
  return encode(filled(width_px, height_px, info.channels, stored), format, jpeg_quality);
}

Result<Picture> transcodeStoredTile(const Archive& archive, const TileId& tile,
                                    PictureFormat format, int jpeg_quality,
                                    const DisplayWindow& window) {
  TESSERA_TRY(checkImage(archive, tile.image));
  TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(tile));
  std::vector<uint8_t> payload;
  if (entry.hasPayload()) {
    TESSERA_ASSIGN_OR_RETURN(payload, archive.readPayload(tile, entry));
  }
  TESSERA_ASSIGN_OR_RETURN(Image stored, archive.decodeTile(tile, entry, payload));
  return encode(eightBit(std::move(stored), window), format, jpeg_quality);
}

}  // namespace tessera::detail
