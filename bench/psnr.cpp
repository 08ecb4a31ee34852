// tessera-psnr: PSNR of a candidate image against a reference, for bench/build_vs_peers.sh.
// Both images are streamed band by band, so memory stays at a few bands whatever their size.
//
// Usage: tessera-psnr REFERENCE CANDIDATE [--band ROWS]
// Each image is one of:
//   - a TIFF or BigTIFF: page 0, tiled or striped, 8-bit, 1..4 samples; JPEG-in-TIFF with YCbCr
//     photometric (vips tiffsave, GDAL COG) is decoded by libtiff with JPEGCOLORMODE_RGB;
//   - a Tessera archive (*.tess): image 0, level 0, through Archive::readRegion;
//   - a Deep Zoom pyramid (*.dzi, or its *_files folder): the deepest level's JPEG tiles.
// Only R, G and B are compared (gray is replicated, alpha ignored).
// Prints one line: `psnr_db=41.23 mse=4.9123 max_abs_diff=87 pixels=1073741824`
// (psnr_db=inf when identical). Exits 1 with a message naming the file on any error.

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <tiffio.h>
#include <turbojpeg.h>

#include <tessera/archive.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace {

using tessera::ErrorCode;
using tessera::fail;
using tessera::Result;

/// An image read top to bottom as packed RGB rows. Owned by one thread.
class RowSource {
 public:
  virtual ~RowSource() = default;
  virtual uint32_t widthPx() const = 0;
  virtual uint32_t heightPx() const = 0;
  /// Fills rows [y, y + rows) into `rgb` (widthPx() * rows * 3 bytes). Calls come in
  /// increasing y, each band starting where the previous one ended.
  virtual Result<void> readRows(uint32_t y, uint32_t rows, uint8_t* rgb) = 0;
};

/// Converts `count` pixels of `channels` 8-bit samples to RGB: gray replicated, alpha dropped.
void toRgb(const uint8_t* src, uint32_t channels, size_t count, uint8_t* rgb) {
  for (size_t i = 0; i < count; ++i, src += channels, rgb += 3) {
    if (channels >= 3) {
      rgb[0] = src[0];
      rgb[1] = src[1];
      rgb[2] = src[2];
    } else {
      rgb[0] = rgb[1] = rgb[2] = src[0];
    }
  }
}

// ---- TIFF (libtiff) -------------------------------------------------------------------------

// libtiff reports errors through a global handler; keep the last message for our error text.
thread_local std::string g_tiff_error;

void tiffErrorHandler(const char* module, const char* format, va_list args) {
  char buffer[512];
  std::vsnprintf(buffer, sizeof(buffer), format, args);
  g_tiff_error = std::string(module ? module : "libtiff") + ": " + buffer;
}

struct TiffCloser {
  void operator()(TIFF* tif) const { TIFFClose(tif); }
};

/// Page 0 of a TIFF. Tiled files are read one row of tiles at a time, striped ones by scanline.
class TiffSource final : public RowSource {
 public:
  static Result<std::unique_ptr<RowSource>> open(const std::string& path) {
    TIFFSetErrorHandler(tiffErrorHandler);
    TIFFSetWarningHandler(nullptr);  // GDAL and vips write private tags libtiff warns about
    std::unique_ptr<TIFF, TiffCloser> tif(TIFFOpen(path.c_str(), "r"));
    if (!tif) return fail(ErrorCode::kIo, path + ": cannot open as TIFF: " + g_tiff_error);
    auto source = std::unique_ptr<TiffSource>(new TiffSource(path));
    uint16_t bits = 8, samples = 1, planar = PLANARCONFIG_CONTIG, format = SAMPLEFORMAT_UINT;
    uint16_t photometric = PHOTOMETRIC_MINISBLACK, compression = COMPRESSION_NONE;
    TIFFGetField(tif.get(), TIFFTAG_IMAGEWIDTH, &source->width_px_);
    TIFFGetField(tif.get(), TIFFTAG_IMAGELENGTH, &source->height_px_);
    TIFFGetFieldDefaulted(tif.get(), TIFFTAG_BITSPERSAMPLE, &bits);
    TIFFGetFieldDefaulted(tif.get(), TIFFTAG_SAMPLESPERPIXEL, &samples);
    TIFFGetFieldDefaulted(tif.get(), TIFFTAG_PLANARCONFIG, &planar);
    TIFFGetFieldDefaulted(tif.get(), TIFFTAG_SAMPLEFORMAT, &format);
    TIFFGetField(tif.get(), TIFFTAG_PHOTOMETRIC, &photometric);
    TIFFGetFieldDefaulted(tif.get(), TIFFTAG_COMPRESSION, &compression);
    if (bits != 8 || format != SAMPLEFORMAT_UINT || samples < 1 || samples > 4) {
      return fail(ErrorCode::kUnsupported,
                  path + ": only 8-bit unsigned samples, 1..4 per pixel, are supported (got " +
                      std::to_string(bits) + "-bit, " + std::to_string(samples) + " samples)");
    }
    if (samples > 1 && planar != PLANARCONFIG_CONTIG) {
      return fail(ErrorCode::kUnsupported, path + ": separate sample planes are not supported");
    }
    if (photometric == PHOTOMETRIC_YCBCR) {
      if (compression != COMPRESSION_JPEG) {
        return fail(ErrorCode::kUnsupported, path + ": YCbCr is supported only inside JPEG");
      }
      // libjpeg converts to RGB and upsamples chroma, so the tile and strip sizes become RGB.
      TIFFSetField(tif.get(), TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
    }
    if (source->width_px_ == 0 || source->height_px_ == 0) {
      return fail(ErrorCode::kCorrupt, path + ": zero width or height");
    }
    source->channels_ = samples;
    source->tiled_ = TIFFIsTiled(tif.get());
    if (source->tiled_) {
      TIFFGetField(tif.get(), TIFFTAG_TILEWIDTH, &source->tile_width_px_);
      TIFFGetField(tif.get(), TIFFTAG_TILELENGTH, &source->tile_height_px_);
      if (source->tile_width_px_ == 0 || source->tile_height_px_ == 0 ||
          source->tile_width_px_ > 8192 || source->tile_height_px_ > 8192) {
        return fail(ErrorCode::kUnsupported, path + ": tile size out of range");
      }
      size_t tiles_x = (source->width_px_ + source->tile_width_px_ - 1) / source->tile_width_px_;
      source->block_.resize(tiles_x * source->tile_width_px_ * source->tile_height_px_ * samples);
      source->tile_.resize(size_t(TIFFTileSize(tif.get())));
    } else {
      source->tile_.resize(size_t(TIFFScanlineSize(tif.get())));
    }
    source->tif_ = std::move(tif);
    return std::unique_ptr<RowSource>(std::move(source));
  }

  uint32_t widthPx() const override { return width_px_; }
  uint32_t heightPx() const override { return height_px_; }

  Result<void> readRows(uint32_t y, uint32_t rows, uint8_t* rgb) override {
    for (uint32_t r = 0; r < rows; ++r) {
      const uint8_t* row = nullptr;
      if (tiled_) {
        uint32_t block = (y + r) / tile_height_px_;
        if (block != block_index_) TESSERA_TRY(loadTileRow(block));
        size_t block_stride = block_.size() / tile_height_px_;
        row = block_.data() + ((y + r) % tile_height_px_) * block_stride;
      } else {
        if (TIFFReadScanline(tif_.get(), tile_.data(), y + r, 0) < 0) {
          return fail(ErrorCode::kCorrupt,
                      path_ + ": row " + std::to_string(y + r) + ": " + g_tiff_error);
        }
        row = tile_.data();
      }
      toRgb(row, channels_, width_px_, rgb + size_t(r) * width_px_ * 3);
    }
    return {};
  }

 private:
  explicit TiffSource(std::string path) : path_(std::move(path)) {}

  /// Decodes every tile of tile row `block` into block_, a full-width band of tile height.
  Result<void> loadTileRow(uint32_t block) {
    size_t block_stride = block_.size() / tile_height_px_;
    size_t tile_stride = size_t(tile_width_px_) * channels_;
    for (uint32_t x = 0; x < width_px_; x += tile_width_px_) {
      ttile_t tile = TIFFComputeTile(tif_.get(), x, block * tile_height_px_, 0, 0);
      tmsize_t got = TIFFReadEncodedTile(tif_.get(), tile, tile_.data(), tmsize_t(tile_.size()));
      if (got < 0) {
        return fail(ErrorCode::kCorrupt,
                    path_ + ": tile " + std::to_string(tile) + ": " + g_tiff_error);
      }
      for (uint32_t ty = 0; ty < tile_height_px_; ++ty) {
        std::memcpy(block_.data() + ty * block_stride + size_t(x) * channels_,
                    tile_.data() + ty * tile_stride, tile_stride);
      }
    }
    block_index_ = block;
    return {};
  }

  std::string path_;
  std::unique_ptr<TIFF, TiffCloser> tif_;
  uint32_t width_px_ = 0;
  uint32_t height_px_ = 0;
  uint32_t channels_ = 0;
  bool tiled_ = false;
  uint32_t tile_width_px_ = 0;
  uint32_t tile_height_px_ = 0;
  uint32_t block_index_ = UINT32_MAX;  ///< tile row held in block_; UINT32_MAX before the first
  std::vector<uint8_t> block_;         ///< tiles_x * tile width by tile height, native samples
  std::vector<uint8_t> tile_;          ///< one decoded tile, or one scanline when striped
};

// ---- Tessera archive ------------------------------------------------------------------------

/// Level 0 of image 0 of an archive, read with Archive::readRegion in column chunks no wider
/// than its 16384 px limit.
class ArchiveSource final : public RowSource {
 public:
  static Result<std::unique_ptr<RowSource>> open(const std::string& path) {
    TESSERA_ASSIGN_OR_RETURN(auto archive, tessera::Archive::openFile(path));
    if (archive->images().empty()) {
      return fail(ErrorCode::kCorrupt, path + ": archive holds no image");
    }
    return std::unique_ptr<RowSource>(new ArchiveSource(std::move(archive)));
  }

  uint32_t widthPx() const override { return archive_->images()[0].width_px; }
  uint32_t heightPx() const override { return archive_->images()[0].height_px; }

  Result<void> readRows(uint32_t y, uint32_t rows, uint8_t* rgb) override {
    constexpr uint32_t kChunkPx = 16384;
    const uint32_t width = widthPx();
    for (uint32_t x = 0; x < width; x += kChunkPx) {
      tessera::PixelRect rect{x, y, std::min(kChunkPx, width - x), rows};
      TESSERA_ASSIGN_OR_RETURN(tessera::Image region, archive_->readRegion(0, 0, rect));
      if (region.width_px != rect.width || region.height_px != rect.height) {
        return fail(ErrorCode::kInternal, archive_->name() + ": readRegion returned " +
                                              std::to_string(region.width_px) + "x" +
                                              std::to_string(region.height_px));
      }
      for (uint32_t r = 0; r < rows; ++r) {
        toRgb(region.row(r), region.channels, rect.width, rgb + (size_t(r) * width + x) * 3);
      }
    }
    return {};
  }

 private:
  explicit ArchiveSource(std::shared_ptr<tessera::Archive> archive)
      : archive_(std::move(archive)) {}
  std::shared_ptr<tessera::Archive> archive_;
};

// ---- Deep Zoom (vips dzsave) ----------------------------------------------------------------

Result<std::vector<uint8_t>> readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(ErrorCode::kNotFound, path.string() + ": cannot open");
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
  if (in.bad()) return fail(ErrorCode::kIo, path.string() + ": read failed");
  return bytes;
}

struct TjCloser {
  void operator()(void* handle) const { tjDestroy(handle); }
};

/// The deepest level of a Deep Zoom pyramid: `NAME_files/<level>/<col>_<row>.jpg`, tiles of
/// `TileSize` plus `Overlap` texels on each inner edge, as described by NAME.dzi.
class DziSource final : public RowSource {
 public:
  static Result<std::unique_ptr<RowSource>> open(const std::string& path) {
    std::filesystem::path dzi = path;
    std::string stem = dzi.string();
    if (std::filesystem::is_directory(dzi)) {
      while (!stem.empty() && stem.back() == '/') stem.pop_back();
      if (stem.size() < 6 || stem.compare(stem.size() - 6, 6, "_files") != 0) {
        return fail(ErrorCode::kInvalidArgument, path + ": a Deep Zoom folder ends in _files");
      }
      stem.resize(stem.size() - 6);
      dzi = stem + ".dzi";
    } else {
      stem = (dzi.parent_path() / dzi.stem()).string();
    }
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> xml_bytes, readFile(dzi));
    std::string xml(xml_bytes.begin(), xml_bytes.end());
    auto source = std::unique_ptr<DziSource>(new DziSource());
    auto attribute = [&](const char* name) -> std::optional<std::string> {
      std::smatch match;
      if (!std::regex_search(xml, match, std::regex(std::string(name) + "=\"([^\"]*)\""))) {
        return std::nullopt;
      }
      return match[1].str();
    };
    auto size = attribute("TileSize"), overlap = attribute("Overlap"), format = attribute("Format"),
         width = attribute("Width"), height = attribute("Height");
    if (!size || !overlap || !format || !width || !height) {
      return fail(ErrorCode::kCorrupt, dzi.string() +
                                           ": missing TileSize, Overlap, Format, "
                                           "Width or Height");
    }
    source->tile_size_px_ = uint32_t(std::stoul(*size));
    source->overlap_px_ = uint32_t(std::stoul(*overlap));
    source->width_px_ = uint32_t(std::stoul(*width));
    source->height_px_ = uint32_t(std::stoul(*height));
    if (*format != "jpg" && *format != "jpeg") {
      return fail(ErrorCode::kUnsupported,
                  dzi.string() + ": tile format " + *format + " (only jpg is supported)");
    }
    if (source->tile_size_px_ == 0 || source->tile_size_px_ > 8192 || source->width_px_ == 0 ||
        source->height_px_ == 0) {
      return fail(ErrorCode::kCorrupt, dzi.string() + ": tile size or dimensions out of range");
    }
    // Deep Zoom: level n has the full size, where 2^n >= max(width, height) > 2^(n-1).
    uint32_t level = 0;
    while ((uint64_t(1) << level) < std::max(source->width_px_, source->height_px_)) ++level;
    source->level_dir_ = std::filesystem::path(stem + "_files") / std::to_string(level);
    source->suffix_ = "." + *format;
    source->tj_.reset(tjInitDecompress());
    size_t tiles_x = (source->width_px_ + source->tile_size_px_ - 1) / source->tile_size_px_;
    source->block_.resize(tiles_x * source->tile_size_px_ * source->tile_size_px_ * 3);
    return std::unique_ptr<RowSource>(std::move(source));
  }

  uint32_t widthPx() const override { return width_px_; }
  uint32_t heightPx() const override { return height_px_; }

  Result<void> readRows(uint32_t y, uint32_t rows, uint8_t* rgb) override {
    const size_t block_stride = block_.size() / tile_size_px_;
    for (uint32_t r = 0; r < rows; ++r) {
      uint32_t block = (y + r) / tile_size_px_;
      if (block != block_index_) TESSERA_TRY(loadTileRow(block));
      std::memcpy(rgb + size_t(r) * width_px_ * 3,
                  block_.data() + ((y + r) % tile_size_px_) * block_stride, size_t(width_px_) * 3);
    }
    return {};
  }

 private:
  DziSource() = default;

  Result<void> loadTileRow(uint32_t row) {
    const size_t block_stride = block_.size() / tile_size_px_;
    const uint32_t rows = std::min(tile_size_px_, height_px_ - row * tile_size_px_);
    for (uint32_t col = 0; col * tile_size_px_ < width_px_; ++col) {
      auto path = level_dir_ / (std::to_string(col) + "_" + std::to_string(row) + suffix_);
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> jpeg, readFile(path));
      int width = 0, height = 0, subsampling = 0, colorspace = 0;
      if (tjDecompressHeader3(tj_.get(), jpeg.data(), jpeg.size(), &width, &height, &subsampling,
                              &colorspace) != 0) {
        return fail(ErrorCode::kCorrupt, path.string() + ": " + tjGetErrorStr2(tj_.get()));
      }
      const uint32_t cols = std::min(tile_size_px_, width_px_ - col * tile_size_px_);
      const uint32_t left = col > 0 ? overlap_px_ : 0, top = row > 0 ? overlap_px_ : 0;
      if (uint32_t(width) < left + cols || uint32_t(height) < top + rows || width > 16384 ||
          height > 16384) {
        return fail(ErrorCode::kCorrupt, path.string() + ": unexpected tile size " +
                                             std::to_string(width) + "x" + std::to_string(height));
      }
      tile_.resize(size_t(width) * height * 3);
      if (tjDecompress2(tj_.get(), jpeg.data(), jpeg.size(), tile_.data(), width, width * 3, height,
                        TJPF_RGB, 0) != 0) {
        return fail(ErrorCode::kCorrupt, path.string() + ": " + tjGetErrorStr2(tj_.get()));
      }
      for (uint32_t ty = 0; ty < rows; ++ty) {
        std::memcpy(block_.data() + ty * block_stride + size_t(col) * tile_size_px_ * 3,
                    tile_.data() + (size_t(top + ty) * width + left) * 3, size_t(cols) * 3);
      }
    }
    block_index_ = row;
    return {};
  }

  std::filesystem::path level_dir_;
  std::string suffix_;
  std::unique_ptr<void, TjCloser> tj_;
  uint32_t tile_size_px_ = 0;
  uint32_t overlap_px_ = 0;
  uint32_t width_px_ = 0;
  uint32_t height_px_ = 0;
  uint32_t block_index_ = UINT32_MAX;  ///< tile row held in block_; UINT32_MAX before the first
  std::vector<uint8_t> block_;         ///< tiles_x * tile size by tile size, RGB
  std::vector<uint8_t> tile_;          ///< one decoded tile with its overlap
};

// ---- main -----------------------------------------------------------------------------------

Result<std::unique_ptr<RowSource>> openSource(const std::string& path) {
  std::filesystem::path p(path);
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (ext == ".tess") return ArchiveSource::open(path);
  if (ext == ".dzi" || std::filesystem::is_directory(p)) return DziSource::open(path);
  return TiffSource::open(path);
}

struct PsnrReport {
  double mse = 0;             ///< mean squared error over R, G and B samples
  double psnr_db = 0;         ///< 10 log10(255^2 / mse); infinity when mse is 0
  unsigned max_abs_diff = 0;  ///< largest absolute difference of one sample
  uint64_t pixels = 0;
};

Result<PsnrReport> compare(RowSource& reference, RowSource& candidate,
                           const std::string& reference_name, const std::string& candidate_name,
                           uint32_t band_rows) {
  if (reference.widthPx() != candidate.widthPx() || reference.heightPx() != candidate.heightPx()) {
    return fail(ErrorCode::kInvalidArgument,
                candidate_name + " is " + std::to_string(candidate.widthPx()) + "x" +
                    std::to_string(candidate.heightPx()) + " but " + reference_name + " is " +
                    std::to_string(reference.widthPx()) + "x" +
                    std::to_string(reference.heightPx()));
  }
  const uint32_t width = reference.widthPx(), height = reference.heightPx();
  std::vector<uint8_t> a(size_t(width) * band_rows * 3), b(a.size());
  uint64_t squared = 0;
  unsigned max_diff = 0;
  for (uint32_t y = 0; y < height; y += band_rows) {
    uint32_t rows = std::min(band_rows, height - y);
    TESSERA_TRY(reference.readRows(y, rows, a.data()));
    TESSERA_TRY(candidate.readRows(y, rows, b.data()));
    size_t count = size_t(width) * rows * 3;
    // 65025 per sample: 64 bits hold the sum for images up to 2^46 pixels.
    for (size_t i = 0; i < count; ++i) {
      int d = int(a[i]) - int(b[i]);
      squared += uint64_t(d * d);
      max_diff = std::max(max_diff, unsigned(d < 0 ? -d : d));
    }
  }
  PsnrReport report;
  report.pixels = uint64_t(width) * height;
  report.mse = double(squared) / (double(report.pixels) * 3);
  report.psnr_db = report.mse == 0 ? INFINITY : 10 * std::log10(255.0 * 255.0 / report.mse);
  report.max_abs_diff = max_diff;
  return report;
}

int usage() {
  std::fprintf(stderr,
               "usage: tessera-psnr REFERENCE CANDIDATE [--band ROWS]\n"
               "  images: TIFF/BigTIFF (page 0), Tessera archive (.tess, level 0),\n"
               "          Deep Zoom (.dzi or NAME_files folder, deepest level, JPEG tiles)\n"
               "  prints: psnr_db=D mse=M max_abs_diff=N pixels=P (R, G, B only)\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> paths;
  uint32_t band_rows = 256;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      usage();
      return 0;
    }
    if (arg == "--band" && i + 1 < argc) {
      band_rows = uint32_t(std::strtoul(argv[++i], nullptr, 10));
      if (band_rows == 0 || band_rows > 16384) return usage();
    } else {
      paths.push_back(arg);
    }
  }
  if (paths.size() != 2) return usage();

  auto reference = openSource(paths[0]);
  if (!reference) {
    std::fprintf(stderr, "tessera-psnr: %s\n", reference.error().message.c_str());
    return 1;
  }
  auto candidate = openSource(paths[1]);
  if (!candidate) {
    std::fprintf(stderr, "tessera-psnr: %s\n", candidate.error().message.c_str());
    return 1;
  }
  auto report = compare(**reference, **candidate, paths[0], paths[1], band_rows);
  if (!report) {
    std::fprintf(stderr, "tessera-psnr: %s\n", report.error().message.c_str());
    return 1;
  }
  if (std::isinf(report->psnr_db)) {
    std::printf("psnr_db=inf mse=0 max_abs_diff=0 pixels=%" PRIu64 "\n", report->pixels);
  } else {
    std::printf("psnr_db=%.2f mse=%.4f max_abs_diff=%u pixels=%" PRIu64 "\n", report->psnr_db,
                report->mse, report->max_abs_diff, report->pixels);
  }
  return 0;
}
