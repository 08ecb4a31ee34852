// Pyramidal TIFF and BigTIFF as an import source: level 0 in the first directory and the
// reduced levels either as its SubIFDs (vips tiffsave --subifd, many slide scanners) or as the
// following directories marked reduced-resolution (COG, GDAL overviews, vips tiffsave
// --pyramid). Raw JPEG tiles are read with TIFFReadRawTile and made whole by splicing the
// directory's JPEGTables in; raw ZSTD tiles of u16 or f32 samples are the zstd codec's payload
// (tessera export --to tiff writes them so); decoded rows come from the ordinary TIFF band
// reader.

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>

#include <fmt/format.h>
#include <tiffio.h>

#include "builder/geotiff_tags.h"
#include "codecs/decode.h"
#include "file_reader.h"
#include "pyramid_source.h"

namespace tessera::detail {
namespace {

// A raw JPEG tile larger than this is hostile: a 2048-px tile stored losslessly is 12 MiB.
constexpr uint64_t kMaxRawTileBytes = uint64_t(64) << 20;
constexpr uint64_t kMaxTablesBytes = uint64_t(1) << 20;
// A pyramid of 2^24 px has 25 levels; slides add a label, a macro and a thumbnail.
constexpr uint32_t kMaxDirectories = 64;

int captureError(TIFF*, void* user_data, const char* module, const char* format, va_list args) {
  auto* to = static_cast<std::string*>(user_data);
  char text[512];
  std::vsnprintf(text, sizeof(text), format, args);
  if (to->size() < 600)
    *to +=
        (to->empty() ? "" : "; ") + std::string(module ? module : "") + (module ? ": " : "") + text;
  return 1;
}

int ignoreWarning(TIFF*, void*, const char*, const char*, va_list) {
  return 1;
}

/// Where a level's directory lives and what its tiles are.
struct TiffLevel {
  TiffImageRef image;
  SourceLevel level;
  std::vector<uint8_t> jpeg_tables;
};

class TiffPyramid final : public PyramidSource {
 public:
  explicit TiffPyramid(std::string path) : path_(std::move(path)) {}
  ~TiffPyramid() override {
    if (tif_) TIFFClose(tif_);
  }
  TiffPyramid(const TiffPyramid&) = delete;
  TiffPyramid& operator=(const TiffPyramid&) = delete;

  /// Reads every directory's tags; false (no error) when the file holds one level only.
  Result<bool> open();
  const SourceInfo& info() const override { return info_; }
  const std::vector<SourceLevel>& levels() const override { return levels_; }
  Result<SourceTile> readTile(uint32_t level, uint32_t x, uint32_t y) override;
  Result<std::unique_ptr<BandReader>> openLevel(uint32_t level) override {
    return openTiffReader(path_, tiff_levels_[level].image);
  }

 private:
  Unexpected failure(const std::string& what) {
    std::string message = fmt::format("{}: {}", path_, what);
    if (!libtiff_error_.empty()) message += " (libtiff: " + libtiff_error_ + ")";
    libtiff_error_.clear();
    return fail(ErrorCode::kCorrupt, std::move(message));
  }
  // The current directory's geometry and whether its tiles can be copied.
  TiffLevel describeDirectory(const TiffImageRef& image) const;
  void describeZstdTiles(uint16_t compression, uint16_t photometric, uint16_t spp, uint16_t bits,
                         uint16_t planar, TiffLevel& out) const;
  Result<SourceTile> zstdTile(uint32_t level, uint32_t x, uint32_t y, uint32_t tile,
                              std::vector<uint8_t> raw);
  Result<void> select(uint32_t level);
  Result<void> checkLevelsAgree() const;

  std::string path_;
  std::string libtiff_error_;  // outlives tif_, whose handler writes it
  TIFF* tif_ = nullptr;
  SourceInfo info_;
  std::vector<TiffLevel> tiff_levels_;
  std::vector<SourceLevel> levels_;
  int selected_ = -1;  // the level whose directory tif_ is on
};

TiffLevel TiffPyramid::describeDirectory(const TiffImageRef& image) const {
  TiffLevel out;
  out.image = image;
  TIFFGetField(tif_, TIFFTAG_IMAGEWIDTH, &out.level.width_px);
  TIFFGetField(tif_, TIFFTAG_IMAGELENGTH, &out.level.height_px);
  uint32_t tile_w = 0, tile_h = 0;
  uint16_t compression = 0, photometric = 0, spp = 1, bits = 8, planar = PLANARCONFIG_CONTIG;
  TIFFGetFieldDefaulted(tif_, TIFFTAG_COMPRESSION, &compression);
  TIFFGetField(tif_, TIFFTAG_PHOTOMETRIC, &photometric);
  TIFFGetFieldDefaulted(tif_, TIFFTAG_SAMPLESPERPIXEL, &spp);
  TIFFGetFieldDefaulted(tif_, TIFFTAG_BITSPERSAMPLE, &bits);
  TIFFGetFieldDefaulted(tif_, TIFFTAG_PLANARCONFIG, &planar);
  if (TIFFIsTiled(tif_)) {
    TIFFGetField(tif_, TIFFTAG_TILEWIDTH, &tile_w);
    TIFFGetField(tif_, TIFFTAG_TILELENGTH, &tile_h);
  }
  if (tile_w == tile_h) out.level.tile_size_px = tile_w;
  // Only YCbCr (decoded to RGB, as the archive's JPEG decoder does) and gray streams mean the
  // same thing outside the TIFF; RGB-photometric JPEG relies on TIFF tags to say so.
  const bool colour_ok = (spp == 3 && photometric == PHOTOMETRIC_YCBCR) ||
                         (spp == 1 && photometric == PHOTOMETRIC_MINISBLACK);
  out.level.jpeg_tiles = out.level.tile_size_px != 0 && compression == COMPRESSION_JPEG &&
                         bits == 8 && (planar == PLANARCONFIG_CONTIG || spp == 1) && colour_ok;
  describeZstdTiles(compression, photometric, spp, bits, planar, out);
  uint32_t tables_bytes = 0;
  void* tables = nullptr;
  if (out.level.jpeg_tiles && TIFFGetField(tif_, TIFFTAG_JPEGTABLES, &tables_bytes, &tables) &&
      tables && tables_bytes <= kMaxTablesBytes) {
    const auto* begin = static_cast<const uint8_t*>(tables);
    out.jpeg_tables.assign(begin, begin + tables_bytes);
  }
  return out;
}

// A ZSTD tile is the zstd codec's payload when nothing but zstd stands between it and the
// packed samples: no predictor, the file's byte order the archive's (little-endian), one plane,
// and a photometric whose samples the band reader passes through unchanged.
void TiffPyramid::describeZstdTiles(uint16_t compression, uint16_t photometric, uint16_t spp,
                                    uint16_t bits, uint16_t planar, TiffLevel& out) const {
  if (out.level.tile_size_px == 0 || compression != COMPRESSION_ZSTD || TIFFIsBigEndian(tif_) ||
      (planar != PLANARCONFIG_CONTIG && spp != 1))
    return;
  const bool colour_ok = (photometric == PHOTOMETRIC_MINISBLACK && spp <= 2) ||
                         (photometric == PHOTOMETRIC_RGB && (spp == 3 || spp == 4));
  uint16_t predictor = PREDICTOR_NONE;
  TIFFGetFieldDefaulted(tif_, TIFFTAG_PREDICTOR, &predictor);
  uint16_t sample_format = 0;
  if (!TIFFGetField(tif_, TIFFTAG_SAMPLEFORMAT, &sample_format))
    sample_format = out.image.missing_sample_format ? out.image.missing_sample_format
                                                    : uint16_t(SAMPLEFORMAT_UINT);
  if (!colour_ok || predictor != PREDICTOR_NONE) return;
  if (sample_format == SAMPLEFORMAT_UINT && bits == 16) {
    out.level.zstd_sample_type = SampleType::kU16;
  } else if (sample_format == SAMPLEFORMAT_IEEEFP && bits == 32) {
    out.level.zstd_sample_type = SampleType::kF32;
  } else {
    return;
  }
  out.level.zstd_tiles = true;
  out.level.zstd_channels = spp;
}

Result<bool> TiffPyramid::open() {
  registerGeoTiffTags();
  TIFFOpenOptions* options = TIFFOpenOptionsAlloc();
  TIFFOpenOptionsSetErrorHandlerExtR(options, captureError, &libtiff_error_);
  TIFFOpenOptionsSetWarningHandlerExtR(options, ignoreWarning, nullptr);
  TIFFOpenOptionsSetMaxSingleMemAlloc(options, tmsize_t(kMaxBandBytes));
  tif_ = TIFFOpenExt(path_.c_str(), "rm", options);
  TIFFOpenOptionsFree(options);
  if (!tif_) return failure("not a readable TIFF");
  tiff_levels_.push_back(describeDirectory({}));
  uint16_t base_sample_format = 0;
  TIFFGetField(tif_, TIFFTAG_SAMPLEFORMAT, &base_sample_format);
  // SubIFDs of the first directory, then the main chain's reduced-resolution directories.
  uint16_t subifd_count = 0;
  uint64_t* subifd_offsets = nullptr;
  std::vector<uint64_t> subifds;
  if (TIFFGetField(tif_, TIFFTAG_SUBIFD, &subifd_count, &subifd_offsets) && subifd_offsets)
    subifds.assign(subifd_offsets, subifd_offsets + subifd_count);
  for (uint64_t offset : subifds) {
    if (!TIFFSetSubDirectory(tif_, offset))
      return failure(fmt::format("cannot read the SubIFD at offset {}", offset));
    tiff_levels_.push_back(describeDirectory({0, offset, base_sample_format}));
  }
  if (subifds.empty()) {
    // TIFFSetDirectory walks the chain from the start: the cap keeps a hostile chain of
    // thousands of directories from costing their square.
    for (uint32_t index = 1; index < kMaxDirectories && TIFFSetDirectory(tif_, tdir_t(index));
         ++index) {
      uint32_t subfile = 0;
      TIFFGetField(tif_, TIFFTAG_SUBFILETYPE, &subfile);
      if ((subfile & FILETYPE_REDUCEDIMAGE) && !(subfile & FILETYPE_MASK))
        tiff_levels_.push_back(describeDirectory({index, 0, base_sample_format}));
    }
  }
  libtiff_error_.clear();
  if (tiff_levels_.size() < 2) return false;
  std::stable_sort(
      tiff_levels_.begin() + 1, tiff_levels_.end(),
      [](const TiffLevel& a, const TiffLevel& b) { return a.level.width_px > b.level.width_px; });
  for (const TiffLevel& level : tiff_levels_) levels_.push_back(level.level);
  TESSERA_TRY(checkLevelsAgree());
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> base, openLevel(0));
  info_ = base->info();
  return true;
}

// A reduced level must shrink both sides by the same factor, to within the rounding of one
// pixel, or it is another picture (a label, a macro photograph) and the pyramid is unusable.
Result<void> TiffPyramid::checkLevelsAgree() const {
  const SourceLevel& base = levels_[0];
  TESSERA_TRY(checkSourceDimensions(path_, base.width_px, base.height_px));
  for (size_t i = 1; i < levels_.size(); ++i) {
    const SourceLevel& level = levels_[i];
    const double expected_height = double(base.height_px) * level.width_px / base.width_px;
    const double factor = double(base.width_px) / std::max(level.width_px, 1u);
    if (level.width_px == 0 || level.height_px == 0 || level.width_px >= levels_[i - 1].width_px ||
        std::abs(level.height_px - expected_height) > 1.0 + factor / level.width_px * 2)
      return fail(
          ErrorCode::kCorrupt,
          fmt::format("{}: pyramid level {} is {}x{} px, which is not a reduction of the "
                      "{}x{} px image (its size or aspect disagrees with the levels above)",
                      path_, i, level.width_px, level.height_px, base.width_px, base.height_px));
  }
  return {};
}

Result<void> TiffPyramid::select(uint32_t level) {
  if (selected_ == int(level)) return {};
  const TiffImageRef& image = tiff_levels_[level].image;
  const int ok = image.subifd_offset ? TIFFSetSubDirectory(tif_, image.subifd_offset)
                                     : TIFFSetDirectory(tif_, tdir_t(image.directory));
  if (!ok) return failure(fmt::format("cannot read the directory of pyramid level {}", level));
  selected_ = int(level);
  return {};
}

Result<SourceTile> TiffPyramid::readTile(uint32_t level, uint32_t x, uint32_t y) {
  TESSERA_TRY(select(level));
  const SourceLevel& geometry = levels_[level];
  const uint32_t side = geometry.tile_size_px;
  const uint32_t tile = TIFFComputeTile(tif_, x * side, y * side, 0, 0);
  const uint64_t bytes = TIFFGetStrileByteCount(tif_, tile);
  SourceTile out;
  if (bytes == 0) {
    // A sparse tile (GDAL's SPARSE_OK) reads as zeros in libtiff; so it does here.
    out.width_px = std::min(side, geometry.width_px - x * side);
    out.height_px = std::min(side, geometry.height_px - y * side);
    out.texels.assign(
        size_t(out.width_px) * out.height_px * info_.channels * sampleBytes(info_.sample_type), 0);
    return out;
  }
  if (bytes > kMaxRawTileBytes)
    return failure(fmt::format("level {} tile ({},{}) claims {} bytes", level, x, y, bytes));
  std::vector<uint8_t> raw(bytes);
  if (TIFFReadRawTile(tif_, tile, raw.data(), tmsize_t(bytes)) != tmsize_t(bytes))
    return failure(fmt::format("level {} tile ({},{}): short read", level, x, y));
  if (geometry.zstd_tiles) return zstdTile(level, x, y, tile, std::move(raw));
  auto whole = completeTiffJpeg(tiff_levels_[level].jpeg_tables, raw);
  if (!whole)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: level {} tile ({},{}): {}", path_, level, x,
                                                 y, whole.error().message));
  out.jpeg = std::move(*whole);
  return out;
}

// Whether the texels right of `width` and below `height` repeat the last column and row, as
// the builder pads an edge tile (cutTile).
bool paddedLikeTheBuilder(const Image& tile, uint32_t width, uint32_t height) {
  const size_t texel = tile.texelBytes();
  for (uint32_t y = 0; y < tile.height_px; ++y) {
    const uint8_t* row = tile.row(y);
    if (y >= height) {
      if (std::memcmp(row, tile.row(height - 1), tile.strideBytes()) != 0) return false;
      continue;
    }
    const uint8_t* last = row + (width - 1) * texel;
    for (uint32_t x = width; x < tile.width_px; ++x)
      if (std::memcmp(row + x * texel, last, texel) != 0) return false;
  }
  return true;
}

// The stored payload when the archive can keep it: one frame recording its size (libtiff's
// own writer leaves the size out, so its tiles are decoded here) and, on the right and bottom
// edges, padding the builder would have written (other writers pad with zeros). Anything else
// comes back as the tile's texels for the builder to pad and encode.
Result<SourceTile> TiffPyramid::zstdTile(uint32_t level, uint32_t x, uint32_t y, uint32_t tile,
                                         std::vector<uint8_t> raw) {
  const SourceLevel& geometry = levels_[level];
  const uint32_t side = geometry.tile_size_px;
  const uint32_t width = std::min(side, geometry.width_px - x * side);
  const uint32_t height = std::min(side, geometry.height_px - y * side);
  const size_t tile_bytes =
      size_t(side) * side * geometry.zstd_channels * sampleBytes(geometry.zstd_sample_type);
  SourceTile out;
  const bool whole_frame = isWholeZstdFrame(raw, tile_bytes);
  if (whole_frame && width == side && height == side) {
    out.zstd = std::move(raw);
    return out;
  }
  Image decoded(side, side, geometry.zstd_channels, geometry.zstd_sample_type);
  if (whole_frame) {
    if (Result<void> done = decodeTile(Codec::kZstd, raw, decoded); !done)
      return failure(fmt::format("level {} tile ({},{}): {}", level, x, y, done.error().message));
    if (paddedLikeTheBuilder(decoded, width, height)) {
      out.zstd = std::move(raw);
      return out;
    }
  } else if (TIFFReadEncodedTile(tif_, tile, decoded.texels.data(),
                                 tmsize_t(decoded.texels.size())) !=
             tmsize_t(decoded.texels.size())) {
    return failure(fmt::format("level {} tile ({},{}) does not decode", level, x, y));
  }
  out.width_px = width;
  out.height_px = height;
  const size_t row_bytes = size_t(width) * decoded.texelBytes();
  out.texels.resize(row_bytes * height);
  for (uint32_t row = 0; row < height; ++row)
    std::memcpy(out.texels.data() + row * row_bytes, decoded.row(row), row_bytes);
  return out;
}

}  // namespace

Result<std::vector<uint8_t>> completeTiffJpeg(std::span<const uint8_t> tables,
                                              std::span<const uint8_t> tile) {
  auto starts_with_soi = [](std::span<const uint8_t> b) {
    return b.size() >= 4 && b[0] == 0xFF && b[1] == 0xD8;
  };
  if (!starts_with_soi(tile)) return fail(ErrorCode::kCorrupt, "tile is not a JPEG stream");
  if (tables.empty()) return std::vector<uint8_t>(tile.begin(), tile.end());
  if (!starts_with_soi(tables) || tables[tables.size() - 2] != 0xFF ||
      tables[tables.size() - 1] != 0xD9)
    return fail(ErrorCode::kCorrupt, "JPEGTables is not an SOI..EOI tables-only stream");
  // SOI, the tables' segments (their own SOI and EOI dropped), then the tile after its SOI:
  // the tile's own tables, if any, come later and win, as in libtiff's decoder.
  std::vector<uint8_t> out;
  out.reserve(tables.size() + tile.size() - 4);
  out.insert(out.end(), tile.begin(), tile.begin() + 2);
  out.insert(out.end(), tables.begin() + 2, tables.end() - 2);
  out.insert(out.end(), tile.begin() + 2, tile.end());
  return out;
}

Result<std::unique_ptr<PyramidSource>> openTiffPyramid(const std::string& path) {
  TESSERA_TRY(checkSourceFile(path));
  auto pyramid = std::make_unique<TiffPyramid>(path);
  TESSERA_ASSIGN_OR_RETURN(const bool is_pyramid, pyramid->open());
  if (!is_pyramid) return std::unique_ptr<PyramidSource>();
  return std::unique_ptr<PyramidSource>(std::move(pyramid));
}

}  // namespace tessera::detail
