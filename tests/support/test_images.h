#pragma once
// Test fixtures written with the real libraries (libtiff, libpng, libjpeg), so reader tests
// see files exactly as other software produces them. Every writer returns "" on success or a
// message saying what failed. Fixtures are small; tests write them into a per-test temp dir.

#include <algorithm>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tessera::test {

/// xorshift32 (Marsaglia): the next of a deterministic sequence from a non-zero `state`, the
/// same on every platform, unlike <random>'s distributions.
inline uint32_t nextRandom(uint32_t& state) {
  state ^= state << 13;
  state ^= state >> 17;
  state ^= state << 5;
  return state;
}

/// Deterministic 8-bit test pixels, `channels` interleaved: smooth gradients plus a little
/// noise, so lossy codecs behave as on photographs and exact round trips catch any byte moved.
std::vector<uint8_t> makeTestPixels(uint32_t width_px, uint32_t height_px, uint32_t channels,
                                    uint32_t seed = 1);

/// GeoTIFF and GDAL tags to write; empty members are not written.
struct GeoTags {
  std::vector<double> model_pixel_scale;     ///< tag 33550
  std::vector<double> model_tiepoint;        ///< tag 33922
  std::vector<double> model_transformation;  ///< tag 34264
  std::vector<uint16_t> geo_key_directory;   ///< tag 34735
  std::vector<double> geo_double_params;     ///< tag 34736
  std::string geo_ascii_params;              ///< tag 34737
  std::string gdal_metadata;                 ///< tag 42112
  std::string gdal_nodata;                   ///< tag 42113
};

/// How to write a TIFF. Values are libtiff's tag values (COMPRESSION_*, PHOTOMETRIC_*, ...).
struct TiffSpec {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint16_t samples = 3;        ///< samples per pixel, extra samples included
  uint16_t bits = 8;           ///< 8, 16 or 32; pixels are widened from the 8-bit input
  uint16_t sample_format = 1;  ///< SAMPLEFORMAT_UINT, _INT or _IEEEFP (32-bit float)
  uint16_t photometric = 2;    ///< PHOTOMETRIC_RGB
  uint16_t compression = 1;    ///< COMPRESSION_NONE
  uint16_t planar = 1;         ///< PLANARCONFIG_CONTIG or _SEPARATE
  uint16_t predictor = 1;      ///< PREDICTOR_NONE or _HORIZONTAL (deflate and LZW)
  bool bigtiff = false;
  bool tiled = false;
  uint32_t tile_width_px = 16;   ///< multiple of 16
  uint32_t tile_height_px = 16;  ///< multiple of 16
  uint32_t rows_per_strip = 8;
  /// ExtraSamples values for samples beyond the photometric's colour samples; defaults to
  /// unassociated alpha for the first and unspecified for the rest.
  std::vector<uint16_t> extra_sample_types;
  /// JPEG compression of RGB data: write it as YCbCr (subsampled) through JPEGCOLORMODE_RGB.
  bool jpeg_ycbcr = true;
  int jpeg_quality = 95;
  GeoTags geo;
};

/// Writes `pixels` (width * height * samples bytes, 8-bit, interleaved) as a TIFF.
std::string writeTiff(const std::string& path, const TiffSpec& spec,
                      const std::vector<uint8_t>& pixels);

/// A minimal hand-made classic TIFF: 8-bit gray, one uncompressed strip holding
/// `data_bytes` bytes, with whatever width and height the header claims (for absurd sizes).
std::vector<uint8_t> makeRawTiffHeader(uint32_t width_px, uint32_t height_px, uint32_t data_bytes);

/// PNG colour types as in png.h.
enum class PngColour { kGray = 0, kRgb = 2, kPalette = 3, kGrayAlpha = 4, kRgba = 6 };

struct PngSpec {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  PngColour colour = PngColour::kRgb;
  int bit_depth = 8;  ///< 1, 2, 4 (gray, palette), 8 or 16
  bool interlaced = false;
  /// kPalette: RGB entries (3 bytes each); pixels are indices.
  std::vector<uint8_t> palette;
  /// tRNS: alpha per palette entry, or for gray/RGB one transparent colour (1 or 3 values).
  std::vector<uint16_t> transparency;
};

/// Writes `pixels` (one byte per sample, width * height * samples; for bit depths under 8 the
/// values must fit; for 16-bit each byte is widened) as a PNG.
std::string writePng(const std::string& path, const PngSpec& spec,
                     const std::vector<uint8_t>& pixels);

/// A PNG signature, an IHDR chunk (valid CRC) claiming any size, an empty IDAT and IEND.
std::vector<uint8_t> makePngHeaderOnly(uint32_t width_px, uint32_t height_px);

struct JpegSpec {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t components = 3;  ///< 1 gray, 3 RGB (stored as YCbCr), 4 CMYK
  int quality = 95;
  bool progressive = false;
};

/// Writes `pixels` (width * height * components bytes) as a JPEG.
std::string writeJpeg(const std::string& path, const JpegSpec& spec,
                      const std::vector<uint8_t>& pixels);

/// Reads a whole file; empty on failure.
std::vector<uint8_t> readFileBytes(const std::string& path);
/// Writes bytes to a file; false on failure.
bool writeFileBytes(const std::string& path, const std::vector<uint8_t>& bytes);

/// Reads every row of a band reader (anything with info() and readRows()) in bands of
/// `band_rows`; on error returns what was read so far and sets `*error` to the message.
template <typename Reader>
std::vector<uint8_t> readAllRows(Reader& reader, uint32_t band_rows, std::string* error) {
  const auto& info = reader.info();
  const size_t row_bytes = size_t(info.width_px) * info.channels * sampleBytes(info.sample_type);
  std::vector<uint8_t> out(row_bytes * info.height_px);
  for (uint32_t y = 0; y < info.height_px; y += band_rows) {
    const uint32_t rows = std::min(band_rows, info.height_px - y);
    auto result =
        reader.readRows(rows, std::span<uint8_t>(out.data() + y * row_bytes, rows * row_bytes));
    if (!result) {
      *error = result.error().message;
      out.resize(y * row_bytes);
      return out;
    }
  }
  error->clear();
  return out;
}

/// A fresh directory for the running test (under ::testing::TempDir()), ending in '/'.
std::string testTempDir();

}  // namespace tessera::test
