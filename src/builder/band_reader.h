#pragma once
// Band readers: sources of image rows for the streaming pyramid builder. A reader yields the
// image top to bottom in bands and never holds the whole image (Backes et al., section 4;
// libvips dzsave's strip-at-a-time design).

#include <algorithm>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera {
struct RowSource;
}  // namespace tessera

namespace tessera::detail {

/// What a reader knows about its image after open.
struct SourceInfo {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t channels = 0;                     ///< 1 gray, 2 gray+alpha, 3 RGB, 4 RGBA
  SampleType sample_type = SampleType::kU8;  ///< what readRows delivers, host byte order
  /// Rows the reader produces most cheaply at once (a TIFF strip or tile row); the builder
  /// asks for bands of about this height. At least 1.
  uint32_t natural_band_rows = 1;
  /// Bytes the reader itself holds while reading (the strip or tile it decodes from, the
  /// decoder's row and coefficient buffers), at most: the build's memory estimate adds it to
  /// the band and the pyramid before anything is allocated.
  uint64_t buffer_bytes = 0;
  /// "tiff", "png", "jpeg", "synthetic".
  std::string format;
  /// Source-specific facts for the archive metadata: for GeoTIFF the georeference
  /// (model tie points, pixel scale, transformation, GeoKey directory, EPSG when known,
  /// GDAL no-data), for TIFF the compression and layout, for synthetic the seed.
  nlohmann::json metadata = nlohmann::json::object();
};

/// Yields rows top to bottom. Owned by one thread. Bad input surfaces as errors naming the
/// file and the problem, never a crash; a reader allocates at most about
/// width x natural_band_rows x channels bytes plus a codec's bounded scratch.
class BandReader {
 public:
  virtual ~BandReader() = default;
  virtual const SourceInfo& info() const = 0;
  /// Fills `out` with the next `rows` rows (tightly packed, width_px * channels bytes each).
  /// Requires rows > 0 and not past the image's end. A decoding error (truncated or corrupt
  /// data) names the file and the row.
  [[nodiscard]] virtual Result<void> readRows(uint32_t rows, std::span<uint8_t> out) = 0;
  /// Moves past the next `rows` rows without delivering them (a part of a split build starts
  /// below the top). Readers that seek (TIFF strips and tiles) read nothing wholly above the
  /// new position; the others read the rows and drop them.
  [[nodiscard]] virtual Result<void> skipRows(uint32_t rows) {
    const size_t row_bytes =
        size_t(info().width_px) * info().channels * sampleBytes(info().sample_type);
    std::vector<uint8_t> dropped;
    for (uint32_t done = 0; done < rows;) {
      const uint32_t n = std::min(rows - done, 64u);
      dropped.resize(row_bytes * n);
      TESSERA_TRY(readRows(n, dropped));
      done += n;
    }
    return {};
  }
  /// Bytes of stored (compressed) strips or tiles read so far, for readers that count them
  /// (TIFF); 0 for the others.
  virtual uint64_t storedBytesRead() const { return 0; }
};

/// Opens a source by name: "synthetic:WxH[:seed]", "grid:COLSxROWS:PATTERN" or a path whose
/// content (not extension) decides between TIFF/BigTIFF, PNG, JPEG and a mosaic manifest (a
/// JSON object, mosaic_reader.h). Fails naming the path and the problem: missing,
/// empty, unrecognised, truncated header, zero or absurd dimensions (over kMaxImageSidePx),
/// unsupported sample format (16-bit, float, palette, CMYK, planar where unsupported).
[[nodiscard]] Result<std::unique_ptr<BandReader>> openBandReader(const std::string& source);

/// One image of a multi-image TIFF: directory `directory` of the main chain, or, when
/// `subifd_offset` is nonzero, the SubIFD at that file offset (a pyramid's reduced levels).
struct TiffImageRef {
  uint32_t directory = 0;
  uint64_t subifd_offset = 0;
  /// SampleFormat for a directory without the tag (0: TIFF's default, unsigned). A pyramid's
  /// reduced levels inherit the base's: vips writes float pyramids whose overviews omit it.
  uint16_t missing_sample_format = 0;
};

/// A TIFF/BigTIFF, PNG or JPEG file by its content, nothing else: the files a grid or a
/// mosaic manifest names. Fails like openBandReader.
[[nodiscard]] Result<std::unique_ptr<BandReader>> openImageFileReader(const std::string& path);

/// Readers by format, used by openBandReader and tests.
[[nodiscard]] Result<std::unique_ptr<BandReader>> openTiffReader(const std::string& path,
                                                                 const TiffImageRef& image = {});
[[nodiscard]] Result<std::unique_ptr<BandReader>> openPngReader(const std::string& path);
[[nodiscard]] Result<std::unique_ptr<BandReader>> openJpegReader(const std::string& path);
/// `spec` is the part after "synthetic:": "WxH[:seed[:channels]]", e.g. "4096x4096:7" or
/// "16384x16384:1:3". Any size up to kMaxImageSidePx per side; 4 channels by default
/// (no-data regions transparent), 3 for RGB (no-data filled with a flat colour).
[[nodiscard]] Result<std::unique_ptr<BandReader>> openSyntheticReader(const std::string& spec);
/// A reader over the caller's callback (tessera/build.h). `source` must outlive the reader.
/// Fails for zero or absurd dimensions, naming the source.
[[nodiscard]] Result<std::unique_ptr<BandReader>> openRowSourceReader(const RowSource& source);

}  // namespace tessera::detail
