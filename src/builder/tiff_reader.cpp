// TIFF/BigTIFF band reader over libtiff 4.5. Striped images are read scanline by scanline or
// strip by strip, tiled images one row of tiles at a time, so memory stays at one band plus
// one strip or tile whatever the image height (libvips' tiff2vips reads the same way).
//
// Accepted: 8- and 16-bit unsigned and 32-bit IEEE float samples (libtiff returns them in
// host byte order and undoes the floating-point predictor), photometric min-is-black, min-is-white
// (inverted to min-is-black), RGB, and YCbCr when JPEG-compressed (libtiff converts to RGB through
// TIFFTAG_JPEGCOLORMODE). Any compression libtiff was built with. Contiguous or separate planes.
// Extra samples: the first one becomes alpha whatever its ExtraSamples type (GDAL writes
// "unspecified" for alpha as often as not); further extra samples are dropped, so a 5-sample
// RGBA + infrared image reads as RGBA. Associated (premultiplied) alpha is passed through as
// stored. Refused with kUnsupported: other bit depths, signed samples, min-is-white with wide
// samples, palette, CMYK and other photometrics.

#include "builder/geotiff_tags.h"

#include <algorithm>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <vector>

#include <fmt/format.h>
#include <tiffio.h>

#include <tessera/format.h>

#include "band_reader.h"
#include "file_reader.h"
#include "uninitialized_buffer.h"

namespace tessera::detail {
namespace {

// GeoKeys holding an EPSG code (GeoTIFF 1.1, sections 7.3.2 and 7.3.3).
constexpr uint16_t kGeoKeyGeographicType = 2048;
constexpr uint16_t kGeoKeyProjectedCsType = 3072;
constexpr uint16_t kGeoKeyUserDefined = 32767;

// Refuse a tag array longer than this: GeoTIFF arrays hold a handful of values and GDAL
// metadata a few KiB, so anything bigger is hostile and would only bloat the archive's JSON.
constexpr uint32_t kMaxGeoValues = 1u << 16;
// Scanline-based layouts have no natural band; this many rows keeps builder calls few
// without holding much (a strip taller than this is read in pieces of this height).
constexpr uint32_t kScanlineBandRows = 256;
// One tile or one planar strip buffered while its pixels are spread into the band.
constexpr uint64_t kMaxUnitBytes = uint64_t(256) << 20;
// libtiff's own allocations (strip arrays, a strip read whole) are capped at the same bound,
// so a hostile directory claiming a 10 GiB strip fails inside libtiff instead of allocating.
constexpr tmsize_t kMaxLibtiffAlloc = tmsize_t(kMaxBandBytes);
constexpr size_t kMaxMessageChars = 600;

const TIFFFieldInfo kGeoTiffFields[] = {
    {kTagModelPixelScale, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("ModelPixelScale")},
    {kTagModelTiepoint, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("ModelTiepoint")},
    {kTagModelTransformation, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("ModelTransformation")},
    {kTagGeoKeyDirectory, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_SHORT, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("GeoKeyDirectory")},
    {kTagGeoDoubleParams, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("GeoDoubleParams")},
    {kTagGeoAsciiParams, TIFF_VARIABLE, TIFF_VARIABLE, TIFF_ASCII, FIELD_CUSTOM, 1, 0,
     const_cast<char*>("GeoAsciiParams")},
    {kTagGdalMetadata, TIFF_VARIABLE, TIFF_VARIABLE, TIFF_ASCII, FIELD_CUSTOM, 1, 0,
     const_cast<char*>("GDALMetadata")},
    {kTagGdalNodata, TIFF_VARIABLE, TIFF_VARIABLE, TIFF_ASCII, FIELD_CUSTOM, 1, 0,
     const_cast<char*>("GDALNoDataValue")},
};

TIFFExtendProc g_previous_extender = nullptr;

void extendWithGeoTiff(TIFF* tif) {
  // Skip tags someone else (libgeotiff in the same process) registered already.
  for (const TIFFFieldInfo& info : kGeoTiffFields) {
    if (!TIFFFindField(tif, info.field_tag, TIFF_ANY)) TIFFMergeFieldInfo(tif, &info, 1);
  }
  if (g_previous_extender) g_previous_extender(tif);
}

// libtiff messages for one handle. Errors accumulate until the reader turns them into a
// Result; warnings are kept (the last few) to explain a later error, except the
// unknown-tag warnings every GIS and scanner TIFF triggers.
struct TiffMessages {
  std::string error;
  std::string warnings;
};

void appendCapped(std::string* to, const char* module, const char* fmt, va_list args) {
  char text[512];
  std::vsnprintf(text, sizeof(text), fmt, args);
  if (to->size() >= kMaxMessageChars) return;
  if (!to->empty()) *to += "; ";
  if (module && *module) *to += std::string(module) + ": ";
  *to += text;
  if (to->size() > kMaxMessageChars) to->resize(kMaxMessageChars);
}

int onTiffError(TIFF*, void* user_data, const char* module, const char* fmt, va_list args) {
  appendCapped(&static_cast<TiffMessages*>(user_data)->error, module, fmt, args);
  return 1;  // handled: keep libtiff's global handler (stderr) quiet
}

int onTiffWarning(TIFF*, void* user_data, const char* module, const char* fmt, va_list args) {
  if (std::strstr(fmt, "nknown field") || std::strstr(fmt, "ASCII value for tag")) return 1;
  appendCapped(&static_cast<TiffMessages*>(user_data)->warnings, module, fmt, args);
  return 1;
}

std::string compressionName(uint16_t compression) {
  switch (compression) {
    case COMPRESSION_NONE: return "none";
    case COMPRESSION_LZW: return "lzw";
    case COMPRESSION_JPEG: return "jpeg";
    case COMPRESSION_OJPEG: return "ojpeg";
    case COMPRESSION_ADOBE_DEFLATE:
    case COMPRESSION_DEFLATE: return "deflate";
    case COMPRESSION_PACKBITS: return "packbits";
    case COMPRESSION_ZSTD: return "zstd";
    case COMPRESSION_WEBP: return "webp";
    case COMPRESSION_LZMA: return "lzma";
    case COMPRESSION_JBIG: return "jbig";
    case COMPRESSION_LERC: return "lerc";
    case COMPRESSION_CCITTRLE:
    case COMPRESSION_CCITTFAX3:
    case COMPRESSION_CCITTFAX4: return "ccitt";
    default: return fmt::format("compression-{}", compression);
  }
}

std::string photometricName(uint16_t photometric) {
  switch (photometric) {
    case PHOTOMETRIC_MINISWHITE: return "min-is-white";
    case PHOTOMETRIC_MINISBLACK: return "min-is-black";
    case PHOTOMETRIC_RGB: return "rgb";
    case PHOTOMETRIC_PALETTE: return "palette";
    case PHOTOMETRIC_MASK: return "transparency mask";
    case PHOTOMETRIC_SEPARATED: return "separated (CMYK)";
    case PHOTOMETRIC_YCBCR: return "ycbcr";
    case PHOTOMETRIC_CIELAB: return "CIE L*a*b*";
    case PHOTOMETRIC_ICCLAB: return "ICC L*a*b*";
    case PHOTOMETRIC_ITULAB: return "ITU L*a*b*";
    case PHOTOMETRIC_LOGL: return "LogL";
    case PHOTOMETRIC_LOGLUV: return "LogLuv";
    default: return fmt::format("photometric {}", photometric);
  }
}

enum class Layout {
  kStripedScanlines,  // contiguous strips, or separate uncompressed: TIFFReadScanline per row
  kSeparateStrips,    // separate compressed strips: one whole strip per plane per band
  kTiles,             // one row of tiles per band
};

class TiffReader final : public BandReader {
 public:
  TiffReader(std::string path, const TiffImageRef& image)
      : path_(std::move(path)), image_(image), messages_(std::make_unique<TiffMessages>()) {}
  ~TiffReader() override {
    if (tif_) TIFFClose(tif_);
  }
  TiffReader(const TiffReader&) = delete;
  TiffReader& operator=(const TiffReader&) = delete;

  Result<void> open();
  const SourceInfo& info() const override { return info_; }
  Result<void> readRows(uint32_t rows, std::span<uint8_t> out) override;
  // Strips and tiles are addressed by row: a skip moves the position, and the next read
  // decodes only the units from there (libtiff seeks to a later strip's start itself).
  Result<void> skipRows(uint32_t rows) override {
    TESSERA_CHECK(rows <= info_.height_px - next_row_)
        << path_ << ": skipRows(" << rows << ") at row " << next_row_ << " of " << info_.height_px;
    next_row_ += rows;
    return {};
  }
  uint64_t storedBytesRead() const override { return stored_bytes_read_; }

 private:
  // Counts the stored bytes of strip or tile `strile` as read.
  void countStrile(uint32_t strile) { stored_bytes_read_ += TIFFGetStrileByteCount(tif_, strile); }
  // An error naming the file, what failed, and what libtiff said about it.
  Unexpected tiffFailure(ErrorCode code, const std::string& what);
  // The file's tags open() decides on.
  struct TiffFormat {
    uint32_t width_px = 0;
    uint32_t height_px = 0;
    uint16_t bits = 0;  // per sample
    uint16_t sample_format = SAMPLEFORMAT_UINT;
    uint16_t photometric = 0;
    uint16_t planar = PLANARCONFIG_CONTIG;
    uint16_t compression = COMPRESSION_NONE;
  };
  // The steps of open(), in order: each fails naming the file and the problem.
  Result<void> openFile();
  Result<TiffFormat> readFormat();  // also sets spp_
  Result<void> checkSamples(const TiffFormat& format);
  // Colour samples per pixel for the photometric (1 or 3); refuses what is not supported.
  Result<uint32_t> colourSamples(const TiffFormat& format);
  // The layout, unit and natural band for tiled and for striped files.
  Result<void> setUpTiles(const TiffFormat& format, nlohmann::json& tiff);
  Result<void> setUpStrips(const TiffFormat& format, nlohmann::json& tiff);
  // Samples of one pixel in a decoded unit: one plane's when separate, else every sample.
  uint64_t samplesPerUnitPixel() const { return separate_ ? 1 : spp_; }
  // Bytes of one output pixel.
  uint64_t pixelBytes() const { return uint64_t(info_.channels) * sample_bytes_; }
  Result<void> readGeoreference();
  /// Decodes the band from `first_row` into `dest`, or into band_ (then valid) when null.
  Result<void> fillBand(uint32_t first_row, uint8_t* dest = nullptr);
  Result<void> readScanline(uint32_t row, uint16_t plane);
  // Spreads `pixels` interleaved samples (spp_ per pixel) into output channels: sample c
  // feeds channel c, samples past the output channels are dropped.
  void convertContiguous(const uint8_t* src, uint8_t* dst, uint32_t pixels) const;
  // Spreads one plane's `pixels` samples into output channel `channel` (plane c feeds
  // channel c; planes past the output channels are never read).
  void convertPlane(const uint8_t* src, uint8_t* dst, uint32_t pixels, uint32_t channel) const;

  std::string path_;
  TiffImageRef image_;
  std::unique_ptr<TiffMessages> messages_;  // outlives tif_, which points at it
  TIFF* tif_ = nullptr;
  SourceInfo info_;

  Layout layout_ = Layout::kStripedScanlines;
  bool separate_ = false;
  uint16_t spp_ = 0;             // samples per pixel in the file
  uint32_t sample_bytes_ = 1;    // 1, 2 or 4: one sample in the file and in the output
  uint32_t rows_per_strip_ = 0;  // striped only, clamped to the height
  uint32_t tile_width_px_ = 0;   // tiled only
  uint32_t tile_height_px_ = 0;  // tiled only
  uint64_t unit_bytes_ = 0;      // bytes of one decoded scanline, strip plane or tile
  uint8_t invert_[4] = {};       // XOR per output channel: 0xff for min-is-white gray
  bool identity_ = false;        // contiguous samples equal output channels byte for byte

  uint32_t next_row_ = 0;
  // Decoded rows [band_first_row_, band_first_row_ + band_rows_) in output channels, for
  // layouts that decode more rows at once than the caller may ask for.
  UninitializedBuffer band_;
  uint32_t band_first_row_ = 0;
  uint32_t band_rows_ = 0;
  UninitializedBuffer unit_;  // one scanline, strip plane or tile as decoded
  uint64_t stored_bytes_read_ = 0;
  uint32_t scanline_strip_ = UINT32_MAX;  // the strip TIFFReadScanline last read from
};

Unexpected TiffReader::tiffFailure(ErrorCode code, const std::string& what) {
  std::string message = fmt::format("{}: {}", path_, what);
  if (!messages_->error.empty()) message += " (libtiff: " + messages_->error + ")";
  if (!messages_->warnings.empty()) message += " (libtiff warnings: " + messages_->warnings + ")";
  messages_->error.clear();
  messages_->warnings.clear();
  return fail(code, std::move(message));
}

Result<void> TiffReader::open() {
  TESSERA_TRY(openFile());
  TESSERA_ASSIGN_OR_RETURN(const TiffFormat format, readFormat());
  TESSERA_TRY(checkSamples(format));
  TESSERA_ASSIGN_OR_RETURN(const uint32_t colour_samples, colourSamples(format));

  const uint32_t extra_samples = spp_ - colour_samples;
  const uint32_t channels = colour_samples + (extra_samples > 0 ? 1 : 0);
  if (format.photometric == PHOTOMETRIC_MINISWHITE) invert_[0] = 0xff;
  separate_ = format.planar == PLANARCONFIG_SEPARATE && spp_ > 1;
  identity_ = !separate_ && spp_ == channels && invert_[0] == 0;

  info_.width_px = format.width_px;
  info_.height_px = format.height_px;
  info_.channels = channels;
  info_.sample_type = sample_bytes_ == 4   ? SampleType::kF32
                      : sample_bytes_ == 2 ? SampleType::kU16
                                           : SampleType::kU8;
  info_.format = "tiff";
  nlohmann::json tiff = {
      {"compression", compressionName(format.compression)},
      {"bigtiff", TIFFIsBigTIFF(tif_) != 0},
      {"planar", separate_ ? "separate" : "contiguous"},
      {"photometric", photometricName(format.photometric)},
      {"samples_per_pixel", spp_},
  };
  if (extra_samples > 1) tiff["dropped_extra_samples"] = extra_samples - 1;
  if (sample_bytes_ != 1 && format.photometric == PHOTOMETRIC_MINISWHITE) {
    return tiffFailure(ErrorCode::kUnsupported,
                       "min-is-white is supported with 8-bit samples only");
  }
  TESSERA_TRY(TIFFIsTiled(tif_) ? setUpTiles(format, tiff) : setUpStrips(format, tiff));
  const uint64_t row_bytes = uint64_t(format.width_px) * pixelBytes();
  if (row_bytes * info_.natural_band_rows > kMaxBandBytes) {
    return tiffFailure(ErrorCode::kTooLarge,
                       fmt::format("a band of {} rows x {} px exceeds the {} MiB limit",
                                   info_.natural_band_rows, format.width_px, kMaxBandBytes >> 20));
  }
  info_.metadata["tiff"] = std::move(tiff);
  TESSERA_TRY(readGeoreference());
  messages_->warnings.clear();
  // The unit, the band it is spread into, and libtiff's raw strip or tile (at most the size of
  // the decoded unit for these codecs, plus its own slack).
  info_.buffer_bytes = 2 * unit_bytes_ + row_bytes * info_.natural_band_rows + (uint64_t(1) << 20);
  unit_.resize(unit_bytes_);
  return {};
}

Result<void> TiffReader::openFile() {
  TIFFOpenOptions* options = TIFFOpenOptionsAlloc();
  TIFFOpenOptionsSetErrorHandlerExtR(options, onTiffError, messages_.get());
  TIFFOpenOptionsSetWarningHandlerExtR(options, onTiffWarning, messages_.get());
  TIFFOpenOptionsSetMaxSingleMemAlloc(options, kMaxLibtiffAlloc);
  // "m": no memory mapping. A mapped source counts every page read towards our RSS and
  // turns an I/O error into SIGBUS; buffered reads keep memory at one band.
  tif_ = TIFFOpenExt(path_.c_str(), "rm", options);
  TIFFOpenOptionsFree(options);
  if (!tif_) return tiffFailure(ErrorCode::kCorrupt, "not a readable TIFF");
  const bool selected = image_.subifd_offset    ? TIFFSetSubDirectory(tif_, image_.subifd_offset)
                        : image_.directory != 0 ? TIFFSetDirectory(tif_, tdir_t(image_.directory))
                                                : 1;
  if (!selected)
    return tiffFailure(ErrorCode::kCorrupt,
                       fmt::format("cannot read directory {} (SubIFD offset {})", image_.directory,
                                   image_.subifd_offset));
  return {};
}

Result<TiffReader::TiffFormat> TiffReader::readFormat() {
  TiffFormat format;
  if (!TIFFGetField(tif_, TIFFTAG_IMAGEWIDTH, &format.width_px) ||
      !TIFFGetField(tif_, TIFFTAG_IMAGELENGTH, &format.height_px)) {
    return tiffFailure(ErrorCode::kCorrupt, "missing ImageWidth or ImageLength");
  }
  TESSERA_TRY(checkSourceDimensions(path_, format.width_px, format.height_px));
  TIFFGetFieldDefaulted(tif_, TIFFTAG_BITSPERSAMPLE, &format.bits);
  TIFFGetFieldDefaulted(tif_, TIFFTAG_SAMPLESPERPIXEL, &spp_);
  if (!TIFFGetField(tif_, TIFFTAG_SAMPLEFORMAT, &format.sample_format))
    format.sample_format =
        image_.missing_sample_format ? image_.missing_sample_format : uint16_t(SAMPLEFORMAT_UINT);
  TIFFGetFieldDefaulted(tif_, TIFFTAG_PLANARCONFIG, &format.planar);
  TIFFGetFieldDefaulted(tif_, TIFFTAG_COMPRESSION, &format.compression);
  if (!TIFFGetField(tif_, TIFFTAG_PHOTOMETRIC, &format.photometric)) {
    return tiffFailure(ErrorCode::kCorrupt, "missing PhotometricInterpretation");
  }
  return format;
}

// The archive stores samples as they are (docs/format.md, "Sample types"): no scaling, so
// other depths are refused rather than converted by a rule the user did not choose.
Result<void> TiffReader::checkSamples(const TiffFormat& format) {
  if (format.sample_format == SAMPLEFORMAT_INT) {
    return tiffFailure(ErrorCode::kUnsupported,
                       "signed integer samples are not supported "
                       "(8- and 16-bit unsigned and 32-bit float are)");
  }
  if (format.sample_format == SAMPLEFORMAT_IEEEFP) {
    if (format.bits != 32) {
      return tiffFailure(ErrorCode::kUnsupported,
                         fmt::format("{}-bit floating-point samples are not supported (32-bit "
                                     "float is)",
                                     format.bits));
    }
    sample_bytes_ = 4;
    return {};
  }
  if (format.sample_format != SAMPLEFORMAT_UINT && format.sample_format != SAMPLEFORMAT_VOID) {
    return tiffFailure(ErrorCode::kUnsupported,
                       fmt::format("sample format {} is not supported", format.sample_format));
  }
  if (format.bits != 8 && format.bits != 16) {
    return tiffFailure(ErrorCode::kUnsupported,
                       fmt::format("{}-bit samples are not supported (8- and 16-bit unsigned and "
                                   "32-bit float are)",
                                   format.bits));
  }
  sample_bytes_ = format.bits / 8;
  return {};
}

Result<uint32_t> TiffReader::colourSamples(const TiffFormat& format) {
  uint32_t colour_samples = 0;
  switch (format.photometric) {
    case PHOTOMETRIC_MINISBLACK:
    case PHOTOMETRIC_MINISWHITE: colour_samples = 1; break;
    case PHOTOMETRIC_RGB: colour_samples = 3; break;
    case PHOTOMETRIC_YCBCR:
      if (format.compression != COMPRESSION_JPEG) {
        return tiffFailure(ErrorCode::kUnsupported,
                           "YCbCr photometric is supported only with JPEG compression");
      }
      colour_samples = 3;
      break;
    case PHOTOMETRIC_PALETTE:
      return tiffFailure(ErrorCode::kUnsupported,
                         "palette (colour-mapped) TIFF is not supported; expand it to RGB first");
    default:
      return tiffFailure(ErrorCode::kUnsupported, fmt::format("{} photometric is not supported",
                                                              photometricName(format.photometric)));
  }
  if (spp_ < colour_samples) {
    return tiffFailure(ErrorCode::kCorrupt, fmt::format("{} samples per pixel for {} photometric",
                                                        spp_, photometricName(format.photometric)));
  }
  if (!TIFFIsCODECConfigured(format.compression)) {
    return tiffFailure(ErrorCode::kUnsupported, fmt::format("compression {} is not supported by "
                                                            "this libtiff",
                                                            compressionName(format.compression)));
  }
  if (format.compression == COMPRESSION_JPEG && format.photometric == PHOTOMETRIC_YCBCR) {
    // Let libjpeg upsample and convert: the scanline and tile sizes then count RGB pixels.
    TIFFSetField(tif_, TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
  }
  return colour_samples;
}

Result<void> TiffReader::setUpTiles(const TiffFormat& format, nlohmann::json& tiff) {
  layout_ = Layout::kTiles;
  TIFFGetField(tif_, TIFFTAG_TILEWIDTH, &tile_width_px_);
  TIFFGetField(tif_, TIFFTAG_TILELENGTH, &tile_height_px_);
  if (tile_width_px_ == 0 || tile_height_px_ == 0) {
    return tiffFailure(ErrorCode::kCorrupt, "zero tile width or height");
  }
  unit_bytes_ = uint64_t(tile_width_px_) * tile_height_px_ * samplesPerUnitPixel() * sample_bytes_;
  if (unit_bytes_ > kMaxUnitBytes) {
    return tiffFailure(ErrorCode::kTooLarge,
                       fmt::format("tiles of {}x{} px exceed the {} MiB limit per tile",
                                   tile_width_px_, tile_height_px_, kMaxUnitBytes >> 20));
  }
  if (TIFFTileSize64(tif_) != unit_bytes_) {
    return tiffFailure(ErrorCode::kUnsupported,
                       fmt::format("unexpected decoded tile size {} (expected {})",
                                   TIFFTileSize64(tif_), unit_bytes_));
  }
  info_.natural_band_rows = std::min(tile_height_px_, format.height_px);
  tiff["layout"] = "tiled";
  tiff["tile_width"] = tile_width_px_;
  tiff["tile_height"] = tile_height_px_;
  return {};
}

Result<void> TiffReader::setUpStrips(const TiffFormat& format, nlohmann::json& tiff) {
  const uint32_t width = format.width_px, height = format.height_px;
  const uint64_t row_bytes = uint64_t(width) * pixelBytes();
  const uint64_t samples_per_unit_pixel = samplesPerUnitPixel() * sample_bytes_;  // in bytes
  uint32_t rows_per_strip = 0;
  TIFFGetFieldDefaulted(tif_, TIFFTAG_ROWSPERSTRIP, &rows_per_strip);
  rows_per_strip_ = std::clamp<uint32_t>(rows_per_strip, 1, height);
  tiff["layout"] = "striped";
  tiff["rows_per_strip"] = rows_per_strip_;
  if (TIFFScanlineSize64(tif_) != uint64_t(width) * samples_per_unit_pixel) {
    return tiffFailure(ErrorCode::kUnsupported,
                       fmt::format("unexpected scanline size {} (expected {})",
                                   TIFFScanlineSize64(tif_), width * samples_per_unit_pixel));
  }
  if (separate_ && format.compression != COMPRESSION_NONE) {
    // Compressed strips cannot be entered mid-way (libtiff has no random access into
    // them), and the planes of one row live in different strips, so a band is a strip.
    layout_ = Layout::kSeparateStrips;
    unit_bytes_ = uint64_t(width) * rows_per_strip_ * sample_bytes_;
    if (unit_bytes_ > kMaxUnitBytes || row_bytes * rows_per_strip_ > kMaxBandBytes) {
      return tiffFailure(ErrorCode::kTooLarge,
                         fmt::format("planar strips of {} rows x {} px exceed the {} MiB limit; "
                                     "rewrite with fewer rows per strip or as tiles",
                                     rows_per_strip_, width, kMaxUnitBytes >> 20));
    }
    info_.natural_band_rows = rows_per_strip_;
    return {};
  }
  // Scanlines: libtiff reads a compressed strip incrementally and chops a single
  // uncompressed strip, so a 100000-row strip costs one scanline of memory here.
  layout_ = Layout::kStripedScanlines;
  unit_bytes_ = uint64_t(width) * samples_per_unit_pixel;
  const uint64_t rows_by_bytes = std::max<uint64_t>(1, (kMaxBandBytes / 16) / row_bytes);
  info_.natural_band_rows =
      uint32_t(std::min<uint64_t>({rows_per_strip_, kScanlineBandRows, rows_by_bytes, height}));
  return {};
}

// Reads a numeric array tag whichever way libtiff knows it: through our extender (uint32
// count) or, if another library registered it first, with a uint16 count.
template <typename T>
bool getArrayTag(TIFF* tif, ttag_t tag, TIFFDataType type, std::vector<T>* values) {
  const TIFFField* field = TIFFFindField(tif, tag, TIFF_ANY);
  if (!field || TIFFFieldDataType(field) != type || !TIFFFieldPassCount(field)) return false;
  const T* data = nullptr;
  uint32_t count = 0;
  if (TIFFFieldReadCount(field) == TIFF_VARIABLE2) {
    if (!TIFFGetField(tif, tag, &count, &data)) return false;
  } else {
    uint16_t count16 = 0;
    if (!TIFFGetField(tif, tag, &count16, &data)) return false;
    count = count16;
  }
  if (!data || count == 0 || count > kMaxGeoValues) return false;
  values->assign(data, data + count);
  return true;
}

bool getAsciiTag(TIFF* tif, ttag_t tag, std::string* value) {
  const TIFFField* field = TIFFFindField(tif, tag, TIFF_ANY);
  if (!field || TIFFFieldDataType(field) != TIFF_ASCII) return false;
  const char* text = nullptr;
  if (TIFFFieldPassCount(field)) {
    uint32_t count = 0;
    uint16_t count16 = 0;
    const bool got = TIFFFieldReadCount(field) == TIFF_VARIABLE2
                         ? TIFFGetField(tif, tag, &count, &text)
                         : TIFFGetField(tif, tag, &count16, &text);
    if (!got || !text) return false;
    if (count == 0) count = count16;
    *value = std::string(text, strnlen(text, std::min(count, kMaxGeoValues)));
  } else {
    if (!TIFFGetField(tif, tag, &text) || !text) return false;
    *value = std::string(text, strnlen(text, kMaxGeoValues));
  }
  return true;
}

Result<void> TiffReader::readGeoreference() {
  nlohmann::json geo = nlohmann::json::object();
  struct DoubleTag {
    ttag_t tag;
    const char* key;
  };
  for (const DoubleTag& entry : {DoubleTag{kTagModelPixelScale, "model_pixel_scale"},
                                 DoubleTag{kTagModelTiepoint, "model_tiepoint"},
                                 DoubleTag{kTagModelTransformation, "model_transformation"},
                                 DoubleTag{kTagGeoDoubleParams, "geo_double_params"}}) {
    std::vector<double> values;
    if (getArrayTag(tif_, entry.tag, TIFF_DOUBLE, &values)) geo[entry.key] = values;
  }
  struct AsciiTag {
    ttag_t tag;
    const char* key;
  };
  for (const AsciiTag& entry :
       {AsciiTag{kTagGeoAsciiParams, "geo_ascii_params"}, AsciiTag{kTagGdalNodata, "gdal_nodata"},
        AsciiTag{kTagGdalMetadata, "gdal_metadata"}}) {
    std::string value;
    if (getAsciiTag(tif_, entry.tag, &value)) geo[entry.key] = value;
  }
  std::vector<uint16_t> keys;
  if (getArrayTag(tif_, kTagGeoKeyDirectory, TIFF_SHORT, &keys)) {
    geo["geo_key_directory"] = keys;
    // Header {version, revision, minor, key count}, then {id, location, count, value} per key;
    // location 0 means the value is the short itself (GeoTIFF 1.1, section 7.1.3).
    if (keys.size() >= 4) {
      const size_t key_count = std::min<size_t>(keys[3], (keys.size() - 4) / 4);
      int geographic = 0, projected = 0;
      for (size_t k = 0; k < key_count; ++k) {
        const uint16_t* key = &keys[4 + 4 * k];
        if (key[1] != 0 || key[3] == 0 || key[3] == kGeoKeyUserDefined) continue;
        if (key[0] == kGeoKeyProjectedCsType) projected = key[3];
        if (key[0] == kGeoKeyGeographicType) geographic = key[3];
      }
      if (projected || geographic) geo["epsg"] = projected ? projected : geographic;
    }
  }
  if (!geo.empty()) info_.metadata["georeference"] = std::move(geo);
  return {};
}

void TiffReader::convertContiguous(const uint8_t* src, uint8_t* dst, uint32_t pixels) const {
  const uint32_t channels = info_.channels;
  if (identity_) {
    std::memcpy(dst, src, size_t(pixels) * pixelBytes());
    return;
  }
  if (sample_bytes_ != 1) {  // wide samples are never inverted: only extra samples dropped
    for (uint32_t x = 0; x < pixels; ++x) {
      std::memcpy(dst, src, pixelBytes());
      src += size_t(spp_) * sample_bytes_;
      dst += pixelBytes();
    }
    return;
  }
  for (uint32_t x = 0; x < pixels; ++x) {
    for (uint32_t c = 0; c < channels; ++c) dst[c] = src[c] ^ invert_[c];
    src += spp_;
    dst += channels;
  }
}

void TiffReader::convertPlane(const uint8_t* src, uint8_t* dst, uint32_t pixels,
                              uint32_t channel) const {
  const uint32_t channels = info_.channels;
  if (sample_bytes_ != 1) {
    const size_t bytes = sample_bytes_;
    for (uint32_t x = 0; x < pixels; ++x)
      std::memcpy(dst + (size_t(x) * channels + channel) * bytes, src + x * bytes, bytes);
    return;
  }
  const uint8_t invert = invert_[channel];
  dst += channel;
  for (uint32_t x = 0; x < pixels; ++x) dst[size_t(x) * channels] = src[x] ^ invert;
}

Result<void> TiffReader::readScanline(uint32_t row, uint16_t plane) {
  const uint32_t strip = TIFFComputeStrip(tif_, row, plane);
  if (strip != scanline_strip_) countStrile(strip);
  scanline_strip_ = strip;
  if (TIFFReadScanline(tif_, unit_.data(), row, plane) < 0) {
    return tiffFailure(ErrorCode::kCorrupt,
                       separate_ ? fmt::format("row {} plane {}: cannot decode", row, plane)
                                 : fmt::format("row {}: cannot decode", row));
  }
  return {};
}

Result<void> TiffReader::fillBand(uint32_t first_row, uint8_t* dest) {
  const uint32_t width = info_.width_px;
  const uint32_t channels = info_.channels;
  const uint32_t band_rows = std::min(info_.natural_band_rows, info_.height_px - first_row);
  const size_t row_bytes = size_t(width) * pixelBytes();
  band_rows_ = 0;  // invalid until filled, so an error leaves no half-filled band behind
  if (!dest) {
    band_.resize(row_bytes * info_.natural_band_rows);
    dest = band_.data();
  }
  const uint16_t planes = separate_ ? uint16_t(std::min<uint32_t>(spp_, channels)) : 1;

  switch (layout_) {
    case Layout::kStripedScanlines:  // separate uncompressed planes (contiguous never buffers)
      for (uint16_t plane = 0; plane < planes; ++plane) {
        for (uint32_t r = 0; r < band_rows; ++r) {
          TESSERA_TRY(readScanline(first_row + r, plane));
          convertPlane(unit_.data(), dest + r * row_bytes, width, plane);
        }
      }
      break;
    case Layout::kSeparateStrips: {
      const uint32_t strip_in_plane = first_row / rows_per_strip_;
      const uint32_t strips_per_plane = TIFFNumberOfStrips(tif_) / spp_;
      for (uint16_t plane = 0; plane < planes; ++plane) {
        const uint32_t strip = plane * strips_per_plane + strip_in_plane;
        const tmsize_t want = tmsize_t(band_rows) * width * sample_bytes_;
        const tmsize_t got = TIFFReadEncodedStrip(tif_, strip, unit_.data(), want);
        countStrile(strip);
        if (got < want) {
          return tiffFailure(ErrorCode::kCorrupt,
                             fmt::format("strip {} (plane {}, rows {}..{}): cannot decode", strip,
                                         plane, first_row, first_row + band_rows - 1));
        }
        for (uint32_t r = 0; r < band_rows; ++r) {
          convertPlane(unit_.data() + size_t(r) * width * sample_bytes_, dest + r * row_bytes,
                       width, plane);
        }
      }
      break;
    }
    case Layout::kTiles: {
      const uint32_t samples = separate_ ? 1 : spp_;
      for (uint32_t tile_x = 0; tile_x < width; tile_x += tile_width_px_) {
        const uint32_t tile_cols = std::min(tile_width_px_, width - tile_x);
        for (uint16_t plane = 0; plane < planes; ++plane) {
          const uint32_t tile = TIFFComputeTile(tif_, tile_x, first_row, 0, plane);
          countStrile(tile);
          if (TIFFReadEncodedTile(tif_, tile, unit_.data(), tmsize_t(unit_bytes_)) < 0) {
            return tiffFailure(
                ErrorCode::kCorrupt,
                fmt::format("tile {} (column {}, rows {}..{}): cannot decode", tile,
                            tile_x / tile_width_px_, first_row, first_row + band_rows - 1));
          }
          for (uint32_t r = 0; r < band_rows; ++r) {
            const uint8_t* src =
                unit_.data() + size_t(r) * tile_width_px_ * samples * sample_bytes_;
            uint8_t* dst = dest + r * row_bytes + size_t(tile_x) * pixelBytes();
            if (separate_) {
              convertPlane(src, dst, tile_cols, plane);
            } else {
              convertContiguous(src, dst, tile_cols);
            }
          }
        }
      }
      break;
    }
  }
  if (dest == band_.data()) {
    band_first_row_ = first_row;
    band_rows_ = band_rows;
  }
  return {};
}

Result<void> TiffReader::readRows(uint32_t rows, std::span<uint8_t> out) {
  const size_t row_bytes = size_t(info_.width_px) * pixelBytes();
  TESSERA_CHECK(rows > 0 && rows <= info_.height_px - next_row_)
      << path_ << ": readRows(" << rows << ") at row " << next_row_ << " of " << info_.height_px;
  TESSERA_CHECK(out.size() >= rows * row_bytes) << path_ << ": output span too small";

  if (layout_ == Layout::kStripedScanlines && !separate_) {
    for (uint32_t r = 0; r < rows; ++r) {
      TESSERA_TRY(readScanline(next_row_, 0));
      convertContiguous(unit_.data(), out.data() + r * row_bytes, info_.width_px);
      ++next_row_;
    }
    return {};
  }
  uint32_t done = 0;
  while (done < rows) {
    if (band_rows_ == 0 || next_row_ < band_first_row_ ||
        next_row_ >= band_first_row_ + band_rows_) {
      const uint32_t band_start = next_row_ - next_row_ % info_.natural_band_rows;
      const uint32_t whole_band = std::min(info_.natural_band_rows, info_.height_px - band_start);
      if (band_start == next_row_ && rows - done >= whole_band) {
        // The caller wants the whole band: decoded in place, one copy fewer.
        TESSERA_TRY(fillBand(band_start, out.data() + done * row_bytes));
        done += whole_band;
        next_row_ += whole_band;
        continue;
      }
      TESSERA_TRY(fillBand(band_start));
    }
    const uint32_t offset = next_row_ - band_first_row_;
    const uint32_t take = std::min(rows - done, band_rows_ - offset);
    std::memcpy(out.data() + done * row_bytes, band_.data() + offset * row_bytes, take * row_bytes);
    done += take;
    next_row_ += take;
  }
  return {};
}

}  // namespace

void registerGeoTiffTags() {
  static std::once_flag once;
  std::call_once(once, [] { g_previous_extender = TIFFSetTagExtender(extendWithGeoTiff); });
}

Result<std::unique_ptr<BandReader>> openTiffReader(const std::string& path,
                                                   const TiffImageRef& image) {
  TESSERA_TRY(checkSourceFile(path));
  registerGeoTiffTags();
  auto reader = std::make_unique<TiffReader>(path, image);
  TESSERA_TRY(reader->open());
  return std::unique_ptr<BandReader>(std::move(reader));
}

}  // namespace tessera::detail
