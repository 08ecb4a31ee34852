// A Deep Zoom folder (NAME.dzi + NAME_files/<level>/<col>_<row>.<format>, as vips dzsave and
// `tessera export --to dzi` write it) as an import source. Deep Zoom level d of an image whose
// larger side is S is ceil(w / 2^(ceil(log2 S) - d)) wide: the archive's ceil rule, so every
// archive level has its Deep Zoom level. Tiles overlap their neighbours by `Overlap` pixels and
// edge tiles are cropped to the image.

#include <algorithm>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>

#include <fmt/format.h>

#include "file_reader.h"
#include "pyramid_source.h"
#include "uninitialized_buffer.h"

namespace tessera::detail {
namespace {

// A .dzi is a few hundred bytes; a tile a few hundred KiB.
constexpr uint64_t kMaxDescriptorBytes = 1 << 16;
constexpr uint64_t kMaxTileFileBytes = uint64_t(64) << 20;
constexpr uint32_t kMaxDeepZoomTilePx = 8192;

// Deep Zoom tiles are JPEG or PNG for browsers; a 16-bit PNG among them is refused by name
// rather than read into an 8-bit band.
Result<void> requireEightBit(const SourceInfo& info, const std::string& path) {
  if (info.sample_type == SampleType::kU8) return {};
  return fail(
      ErrorCode::kUnsupported,
      fmt::format("{}: a Deep Zoom tile with {} samples; Deep Zoom import reads 8-bit tiles", path,
                  sampleTypeName(info.sample_type)));
}

Result<std::vector<uint8_t>> readWholeFile(const std::string& path, uint64_t limit) {
  TESSERA_ASSIGN_OR_RETURN(const uint64_t size, checkSourceFile(path));
  if (size > limit)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {} bytes, over {}", path, size, limit));
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> bytes(size);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(size)))
    return fail(ErrorCode::kIo, path + ": cannot read");
  return bytes;
}

struct DeepZoomLayout {
  std::string files_dir;  ///< NAME_files
  std::string format;     ///< tile file extension: jpg, jpeg or png
  uint32_t tile_size_px = 0;
  uint32_t overlap_px = 0;
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t max_level = 0;  ///< the Deep Zoom level of full resolution

  std::string tilePath(uint32_t level, uint32_t x, uint32_t y) const {
    return fmt::format("{}/{}/{}_{}.{}", files_dir, max_level - level, x, y, format);
  }
  uint32_t levelWidth(uint32_t level) const {
    return uint32_t((uint64_t(width_px) + (uint64_t(1) << level) - 1) >> level);
  }
  uint32_t levelHeight(uint32_t level) const {
    return uint32_t((uint64_t(height_px) + (uint64_t(1) << level) - 1) >> level);
  }
};

// The attribute `name` of the descriptor, as a whole number; fails naming the file.
Result<uint64_t> attribute(const std::string& path, const std::string& xml,
                           const std::string& name) {
  const std::regex pattern("\\b" + name + "\\s*=\\s*\"([0-9]{1,9})\"");
  std::smatch match;
  if (!std::regex_search(xml, match, pattern))
    return fail(ErrorCode::kCorrupt, fmt::format("{}: no {} attribute", path, name));
  return std::stoull(match[1].str());
}

Result<DeepZoomLayout> readDescriptor(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, readWholeFile(path, kMaxDescriptorBytes));
  const std::string xml(bytes.begin(), bytes.end());
  DeepZoomLayout layout;
  std::smatch match;
  if (!std::regex_search(xml, match, std::regex("\\bFormat\\s*=\\s*\"([A-Za-z]{1,8})\"")))
    return fail(ErrorCode::kCorrupt, path + ": not a Deep Zoom descriptor (no Format attribute)");
  layout.format = match[1].str();
  TESSERA_ASSIGN_OR_RETURN(const uint64_t tile, attribute(path, xml, "TileSize"));
  TESSERA_ASSIGN_OR_RETURN(const uint64_t overlap, attribute(path, xml, "Overlap"));
  TESSERA_ASSIGN_OR_RETURN(const uint64_t width, attribute(path, xml, "Width"));
  TESSERA_ASSIGN_OR_RETURN(const uint64_t height, attribute(path, xml, "Height"));
  if (tile == 0 || tile > kMaxDeepZoomTilePx || overlap > tile)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: TileSize {} with Overlap {} is out of range",
                                                 path, tile, overlap));
  TESSERA_TRY(checkSourceDimensions(path, width, height));
  layout.tile_size_px = uint32_t(tile);
  layout.overlap_px = uint32_t(overlap);
  layout.width_px = uint32_t(width);
  layout.height_px = uint32_t(height);
  while ((uint64_t(1) << layout.max_level) < std::max(width, height)) ++layout.max_level;
  layout.files_dir = path.substr(0, path.size() - 4) + "_files";
  return layout;
}

// The decoded rows of one Deep Zoom level, a row of tiles at a time.
class DeepZoomLevelReader final : public BandReader {
 public:
  DeepZoomLevelReader(const DeepZoomLayout& layout, uint32_t level)
      : layout_(layout), level_(level) {}

  Result<void> open(uint32_t channels) {
    info_.width_px = layout_.levelWidth(level_);
    info_.height_px = layout_.levelHeight(level_);
    info_.channels = channels;
    info_.natural_band_rows = std::min(layout_.tile_size_px, info_.height_px);
    info_.format = "dzi";
    info_.metadata["dzi"] = {{"tile_size", layout_.tile_size_px},
                             {"overlap", layout_.overlap_px},
                             {"format", layout_.format}};
    const uint64_t side = layout_.tile_size_px + 2 * layout_.overlap_px;
    const uint64_t band_bytes = uint64_t(info_.width_px) * info_.natural_band_rows * channels;
    info_.buffer_bytes = band_bytes + side * side * 4;
    band_.resize(band_bytes);
    return {};
  }
  const SourceInfo& info() const override { return info_; }

  Result<void> readRows(uint32_t rows, std::span<uint8_t> out) override {
    const size_t row_bytes = size_t(info_.width_px) * info_.channels;
    for (uint32_t done = 0; done < rows;) {
      const uint32_t band_row = next_row_ / layout_.tile_size_px;
      if (!band_valid_ || band_row != band_row_) TESSERA_TRY(fillBand(band_row));
      const uint32_t offset = next_row_ - band_row * layout_.tile_size_px;
      const uint32_t take = std::min(rows - done, band_rows_ - offset);
      std::memcpy(out.data() + done * row_bytes, band_.data() + offset * row_bytes,
                  take * row_bytes);
      done += take;
      next_row_ += take;
    }
    return {};
  }

 private:
  Result<void> fillBand(uint32_t tile_row) {
    const uint32_t ts = layout_.tile_size_px;
    band_rows_ = std::min(ts, info_.height_px - tile_row * ts);
    const uint32_t tiles_x = (info_.width_px + ts - 1) / ts;
    for (uint32_t x = 0; x < tiles_x; ++x) {
      const std::string path = layout_.tilePath(level_, x, tile_row);
      TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> tile, openBandReader(path));
      const SourceInfo& tile_info = tile->info();
      const uint32_t left = x > 0 ? layout_.overlap_px : 0;
      const uint32_t top = tile_row > 0 ? layout_.overlap_px : 0;
      const uint32_t width = std::min(ts, info_.width_px - x * ts);
      TESSERA_TRY(requireEightBit(tile_info, path));
      if (tile_info.channels != info_.channels || tile_info.width_px < left + width ||
          tile_info.height_px < top + band_rows_)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: {}x{} px with {} channel(s), expected at least {}x{} with {}",
                                path, tile_info.width_px, tile_info.height_px, tile_info.channels,
                                left + width, top + band_rows_, info_.channels));
      const size_t tile_row_bytes = size_t(tile_info.width_px) * info_.channels;
      scratch_.resize(tile_row_bytes * (top + band_rows_));
      TESSERA_TRY(tile->readRows(top + band_rows_, {scratch_.data(), scratch_.size()}));
      for (uint32_t r = 0; r < band_rows_; ++r)
        std::memcpy(band_.data() + (size_t(r) * info_.width_px + size_t(x) * ts) * info_.channels,
                    scratch_.data() + (r + top) * tile_row_bytes + left * info_.channels,
                    size_t(width) * info_.channels);
    }
    band_row_ = tile_row;
    band_valid_ = true;
    return {};
  }

  const DeepZoomLayout layout_;
  const uint32_t level_;  // counted from full resolution, as the archive's
  SourceInfo info_;
  UninitializedBuffer band_;  // one row of tiles, decoded and stitched
  std::vector<uint8_t> scratch_;
  uint32_t band_row_ = 0, band_rows_ = 0, next_row_ = 0;
  bool band_valid_ = false;
};

class DeepZoomPyramid final : public PyramidSource {
 public:
  explicit DeepZoomPyramid(DeepZoomLayout layout) : layout_(std::move(layout)) {}

  Result<void> open(const std::string& path) {
    const bool jpeg = layout_.format == "jpg" || layout_.format == "jpeg";
    for (uint32_t l = 0; l <= layout_.max_level; ++l) {
      SourceLevel level;
      level.width_px = layout_.levelWidth(l);
      level.height_px = layout_.levelHeight(l);
      level.tile_size_px = layout_.overlap_px == 0 ? layout_.tile_size_px : 0;
      level.jpeg_tiles = jpeg && layout_.overlap_px == 0;
      levels_.push_back(level);
    }
    // The first tile says what the image's channels are.
    TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> first,
                             openBandReader(layout_.tilePath(0, 0, 0)));
    TESSERA_TRY(requireEightBit(first->info(), layout_.tilePath(0, 0, 0)));
    channels_ = first->info().channels;
    TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> base, openLevel(0));
    info_ = base->info();
    info_.metadata["dzi"]["descriptor"] = path;
    return {};
  }
  const SourceInfo& info() const override { return info_; }
  const std::vector<SourceLevel>& levels() const override { return levels_; }

  Result<SourceTile> readTile(uint32_t level, uint32_t x, uint32_t y) override {
    const std::string path = layout_.tilePath(level, x, y);
    const uint32_t ts = layout_.tile_size_px;
    const uint32_t width = std::min(ts, levels_[level].width_px - x * ts);
    const uint32_t height = std::min(ts, levels_[level].height_px - y * ts);
    SourceTile tile;
    if (width == ts && height == ts) {
      TESSERA_ASSIGN_OR_RETURN(tile.jpeg, readWholeFile(path, kMaxTileFileBytes));
      return tile;
    }
    // Edge tiles are cropped to the image: decoded here, padded and encoded by the builder.
    TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> reader, openBandReader(path));
    TESSERA_TRY(requireEightBit(reader->info(), path));
    if (reader->info().width_px != width || reader->info().height_px != height ||
        reader->info().channels != channels_)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: {}x{} px with {} channel(s), expected {}x{} with {}", path,
                              reader->info().width_px, reader->info().height_px,
                              reader->info().channels, width, height, channels_));
    tile.width_px = width;
    tile.height_px = height;
    tile.texels.resize(size_t(width) * height * channels_);
    TESSERA_TRY(reader->readRows(height, tile.texels));
    return tile;
  }

  Result<std::unique_ptr<BandReader>> openLevel(uint32_t level) override {
    auto reader = std::make_unique<DeepZoomLevelReader>(layout_, level);
    TESSERA_TRY(reader->open(channels_));
    return std::unique_ptr<BandReader>(std::move(reader));
  }

 private:
  DeepZoomLayout layout_;
  SourceInfo info_;
  std::vector<SourceLevel> levels_;
  uint32_t channels_ = 0;
};

}  // namespace

Result<std::unique_ptr<PyramidSource>> openDeepZoom(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(DeepZoomLayout layout, readDescriptor(path));
  auto pyramid = std::make_unique<DeepZoomPyramid>(std::move(layout));
  TESSERA_TRY(pyramid->open(path));
  return std::unique_ptr<PyramidSource>(std::move(pyramid));
}

}  // namespace tessera::detail
