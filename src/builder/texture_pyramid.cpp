#include "builder/texture_pyramid.h"

#include <cstring>

#include <fmt/format.h>

#include "band_reader.h"
#include "build_internals.h"
#include "format/checksum.h"
#include "format/header.h"
#include "pyramid_builder.h"
#include "tile_cutter.h"

namespace tessera::detail {

namespace {

// Encodes each tile row as the streaming pyramid announces it.
class PyramidSink final : public TileSink {
 public:
  PyramidSink(EncodedPyramid& out, Codec codec, const EncodeOptions& options, CodecScratch* scratch,
              const std::string& what)
      : out_(out), codec_(codec), options_(options), scratch_(scratch), what_(what) {
    tile_.resize(out.info.storedTileBytes());
  }

  Result<void> tileRowReady(uint32_t level, uint32_t tile_row, const LevelRows& rows) override {
    const ImageInfo& info = out_.info;
    const uint32_t side = info.storedTileSidePx();
    for (uint32_t x = 0; x < info.tilesX(level); ++x) {
      cutTile(rows, info.tile_size_px, info.border_px, x, tile_row, tile_.data());
      const size_t slot = size_t(tile_row) * info.tilesX(level) + x;
      TileEntry& entry = out_.entries[level][slot];
      uint32_t colour = 0;
      if (isUniform(&colour)) {
        const bool has_alpha = info.channels == 2 || info.channels == 4;
        entry.kind = has_alpha && colour == 0 ? TileKind::kEmpty : TileKind::kUniform;
        entry.uniform_rgba = entry.kind == TileKind::kUniform ? colour : 0;
        continue;
      }
      ImageView view{tile_.data(), side, side, info.channels, size_t(side) * info.channels};
      auto payload = encodeTile(codec_, view, options_, nullptr, scratch_);
      if (!payload)
        return fail(payload.error().code, fmt::format("{}: tile ({},{},{}): {}", what_, level, x,
                                                      tile_row, payload.error().message));
      if (payload->size() > UINT32_MAX)
        return fail(ErrorCode::kTooLarge, what_ + ": payload over 4 GiB");
      entry.kind = TileKind::kEncoded;
      entry.codec = codec_;
      entry.length_bytes = uint32_t(payload->size());
      entry.checksum = checksum64(*payload);
      out_.payloads[level][slot] = std::move(*payload);
    }
    return {};
  }

 private:
  // Every texel, border and padding included, equal to the first.
  bool isUniform(uint32_t* colour) const {
    const uint32_t channels = out_.info.channels;
    for (size_t i = channels; i < tile_.size(); i += channels)
      if (std::memcmp(tile_.data() + i, tile_.data(), channels) != 0) return false;
    *colour = 0;
    for (uint32_t c = 0; c < channels; ++c) *colour |= uint32_t(tile_[c]) << (8 * c);
    return true;
  }

  EncodedPyramid& out_;
  Codec codec_;
  const EncodeOptions& options_;
  CodecScratch* scratch_;
  const std::string& what_;
  std::vector<uint8_t> tile_;
};

}  // namespace

Result<Image> readImageFile(const std::string& path, uint32_t max_side_px) {
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> reader, openBandReader(path));
  const SourceInfo& source = reader->info();
  if (source.width_px > max_side_px || source.height_px > max_side_px)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {}x{} texture exceeds the {} px limit per side", path,
                            source.width_px, source.height_px, max_side_px));
  Image image(source.width_px, source.height_px, source.channels, source.sample_type);
  const size_t row_bytes = image.strideBytes();
  const uint32_t band = std::max(1u, std::min(source.natural_band_rows, 256u));
  for (uint32_t y = 0; y < image.height_px;) {
    const uint32_t rows = std::min(band, image.height_px - y);
    TESSERA_TRY(reader->readRows(rows, {image.row(y), row_bytes * rows}));
    y += rows;
  }
  return image;
}

nlohmann::json levelStatistics(const Image& level) {
  struct ImageRows final : LevelRows {
    const Image* image = nullptr;
    const uint8_t* row(uint32_t y) const override { return image->row(y); }
  } rows;
  rows.image = &level;
  rows.width_px = level.width_px;
  rows.height_px = level.height_px;
  rows.channels = level.channels;
  rows.sample_type = level.sample_type;
  return level.sample_type == SampleType::kU8 ? coarsestLevelStatistics(rows)
                                              : wideLevelStatistics(rows);
}

Image toEightBit(Image image) {
  if (image.sample_type == SampleType::kU8) return image;
  Image narrow(image.width_px, image.height_px, image.channels);
  const size_t samples = narrow.texels.size();
  if (image.sample_type == SampleType::kU16) {
    for (size_t i = 0; i < samples; ++i) {
      uint16_t v;
      std::memcpy(&v, image.texels.data() + 2 * i, 2);
      narrow.texels[i] = uint8_t((uint32_t(v) * 255 + 32767) / 65535);
    }
  } else {
    for (size_t i = 0; i < samples; ++i) {
      float v;
      std::memcpy(&v, image.texels.data() + 4 * i, 4);
      // NaN fails both comparisons and lands on 0, like a value below the range.
      const float clamped = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f;
      narrow.texels[i] = uint8_t(clamped * 255.0f + 0.5f);
    }
  }
  return narrow;
}

Result<EncodedPyramid> encodePyramid(const Image& image, ImageInfo info, Codec codec,
                                     const EncodeOptions& options, CodecScratch* scratch,
                                     const std::string& what) {
  TESSERA_CHECK(image.width_px == info.width_px && image.height_px == info.height_px &&
                image.channels == info.channels)
      << "encodePyramid: image and info disagree";
  if (codecNeedsParent(codec))
    return fail(
        ErrorCode::kUnsupported,
        fmt::format("{}: codec {} is not supported for scene textures", what, codecName(codec)));
  TESSERA_TRY(validateImageInfo(info, what));
  info.level_count = levelCountFor(info.width_px, info.height_px, info.tile_size_px);
  info.default_codec = codec;
  EncodedPyramid out;
  out.info = info;
  out.entries.resize(info.level_count);
  out.payloads.resize(info.level_count);
  for (uint32_t level = 0; level < info.level_count; ++level) {
    const size_t tiles = size_t(info.tilesX(level)) * info.tilesY(level);
    out.entries[level].resize(tiles);
    out.payloads[level].resize(tiles);
  }
  PyramidSink sink(out, codec, options, scratch, what);
  PyramidBuilder pyramid(out.info, sink);
  TESSERA_TRY(pyramid.addRows(image.texels.data(), image.height_px));
  TESSERA_TRY(pyramid.finish());
  return out;
}

}  // namespace tessera::detail
