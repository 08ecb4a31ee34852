// A tiled pyramidal BigTIFF, as `vips tiffsave --tile --pyramid` and COGs lay it out: level 0
// in the first directory, each coarser level in the next one (a reduced-resolution image),
// tiles the archive's tile size. Tessera's levels are padded to whole tiles exactly as TIFF's
// are, so a JPEG archive without border has its payloads written as they are, edge tiles
// included (TIFF readers ignore the padding); other 8-bit archives are decoded and stored with
// Deflate and the horizontal predictor, losslessly. u16 and f32 images keep their samples: a
// zstd payload is a TIFF ZSTD tile byte for byte and is copied, anything else is decoded and
// compressed again by libtiff. A GeoTIFF source's georeference, kept in the archive's metadata,
// goes back on level 0's directory.
#include <tiffio.h>

#include <algorithm>
#include <filesystem>
#include <memory>
#include <span>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "builder/geotiff_tags.h"
#include "codecs/decode.h"
#include "codecs/encode.h"
#include "export_writers.h"
#include "serve/image_metadata.h"

namespace tessera::detail {

namespace {

struct TiffCloser {
  void operator()(TIFF* tiff) const { TIFFClose(tiff); }
};
using TiffFile = std::unique_ptr<TIFF, TiffCloser>;

struct Sampling {
  uint16_t horizontal = 0, vertical = 0;  ///< of the luma component; 0 when not found
  friend bool operator==(const Sampling&, const Sampling&) = default;
};

// The first component's sampling factors in a JPEG stream's frame header (SOF0..SOF2).
Sampling jpegSampling(std::span<const uint8_t> bytes) {
  for (size_t i = 2; i + 11 < bytes.size();) {
    if (bytes[i] != 0xFF) return {};
    const uint8_t marker = bytes[i + 1];
    const size_t length = (size_t(bytes[i + 2]) << 8) | bytes[i + 3];
    if (marker >= 0xC0 && marker <= 0xC2) {
      if (i + 11 >= bytes.size() || bytes[i + 9] < 1) return {};
      const uint8_t factors = bytes[i + 11];
      return {uint16_t(factors >> 4), uint16_t(factors & 0x0F)};
    }
    i += 2 + length;
  }
  return {};
}

// How the image's tiles are compressed in the TIFF, the same for every level.
struct TiffEncoding {
  uint16_t compression = COMPRESSION_ADOBE_DEFLATE;
  uint16_t predictor = PREDICTOR_HORIZONTAL;  ///< unused with JPEG
  bool copy_jpeg = false;  ///< JPEG payloads are written as they are, the rest encoded as JPEG
  bool copy_zstd = false;  ///< zstd payloads are written as they are, the rest through libtiff
  const char* name = "deflate";  ///< for the report
};

TiffEncoding chooseEncoding(const ImageInfo& info) {
  TiffEncoding encoding;
  if (info.sample_type == SampleType::kU8) {
    if (info.default_codec == Codec::kJpeg && info.border_px == 0 &&
        (info.channels == 1 || info.channels == 3)) {
      encoding.compression = COMPRESSION_JPEG;
      encoding.copy_jpeg = true;
      encoding.name = "jpeg";
    }
    return encoding;
  }
  // Tessera's zstd payload is one frame of the tile's packed little-endian samples, channels
  // interleaved: what a TIFF ZSTD tile of a little-endian file decompresses to when the
  // predictor is none. The predictor is per directory, so it is left out whenever payloads
  // are copied; otherwise libtiff's own predictor for the type helps the compression.
  encoding.predictor =
      info.sample_type == SampleType::kF32 ? PREDICTOR_FLOATINGPOINT : PREDICTOR_HORIZONTAL;
  if (TIFFIsCODECConfigured(COMPRESSION_ZSTD)) {
    encoding.compression = COMPRESSION_ZSTD;
    encoding.name = "zstd";
    if (info.default_codec == Codec::kZstd && info.border_px == 0) {
      encoding.copy_zstd = true;
      encoding.predictor = PREDICTOR_NONE;
    }
  }
  return encoding;
}

struct LevelPlan {
  TiffEncoding encoding;
  Sampling sampling{2, 2};  ///< of the JPEG tiles, when they are copied
};

Result<LevelPlan> planLevel(const Archive& archive, const ImageInfo& info, uint32_t image,
                            uint32_t level) {
  LevelPlan plan;
  plan.encoding = chooseEncoding(info);
  if (!plan.encoding.copy_jpeg || info.channels == 1) return plan;
  // The file states one subsampling per level: that of the first stored JPEG payload.
  for (uint32_t y = 0; y < info.tilesY(level); ++y) {
    for (uint32_t x = 0; x < info.tilesX(level); ++x) {
      const TileId tile{image, level, x, y};
      TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(tile));
      if (entry.kind != TileKind::kEncoded || entry.codec != Codec::kJpeg) continue;
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload, archive.readPayload(tile, entry));
      const Sampling sampling = jpegSampling(payload);
      if (sampling.horizontal != 0) plan.sampling = sampling;
      return plan;
    }
  }
  return plan;
}

void setLevelTags(TIFF* tiff, const ImageInfo& info, uint32_t level, const LevelPlan& plan) {
  TIFFSetField(tiff, TIFFTAG_SUBFILETYPE, level == 0 ? 0 : FILETYPE_REDUCEDIMAGE);
  TIFFSetField(tiff, TIFFTAG_IMAGEWIDTH, info.levelWidthPx(level));
  TIFFSetField(tiff, TIFFTAG_IMAGELENGTH, info.levelHeightPx(level));
  TIFFSetField(tiff, TIFFTAG_TILEWIDTH, info.tile_size_px);
  TIFFSetField(tiff, TIFFTAG_TILELENGTH, info.tile_size_px);
  TIFFSetField(tiff, TIFFTAG_BITSPERSAMPLE, 8 * sampleBytes(info.sample_type));
  if (info.sample_type != SampleType::kU8)
    TIFFSetField(tiff, TIFFTAG_SAMPLEFORMAT,
                 info.sample_type == SampleType::kF32 ? SAMPLEFORMAT_IEEEFP : SAMPLEFORMAT_UINT);
  TIFFSetField(tiff, TIFFTAG_SAMPLESPERPIXEL, info.channels);
  TIFFSetField(tiff, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(tiff, TIFFTAG_SOFTWARE, "tessera export");
  const bool color = info.channels >= 3;
  if (plan.encoding.copy_jpeg) {
    TIFFSetField(tiff, TIFFTAG_COMPRESSION, COMPRESSION_JPEG);
    // Each tile is a whole JPEG stream with its own tables.
    TIFFSetField(tiff, TIFFTAG_JPEGTABLESMODE, 0);
    TIFFSetField(tiff, TIFFTAG_PHOTOMETRIC, color ? PHOTOMETRIC_YCBCR : PHOTOMETRIC_MINISBLACK);
    if (color)
      TIFFSetField(tiff, TIFFTAG_YCBCRSUBSAMPLING, plan.sampling.horizontal,
                   plan.sampling.vertical);
    return;
  }
  TIFFSetField(tiff, TIFFTAG_COMPRESSION, plan.encoding.compression);
  TIFFSetField(tiff, TIFFTAG_PREDICTOR, plan.encoding.predictor);
  // Level 1, as the archive's zstd codec: libtiff's default 9 saved 6 % on a 4096 x 4096 u16
  // image and took four times as long (docs/export.md).
  if (plan.encoding.compression == COMPRESSION_ZSTD) TIFFSetField(tiff, TIFFTAG_ZSTD_LEVEL, 1);
  TIFFSetField(tiff, TIFFTAG_PHOTOMETRIC, color ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK);
  if (info.channels == 2 || info.channels == 4) {
    const uint16_t alpha = EXTRASAMPLE_UNASSALPHA;
    TIFFSetField(tiff, TIFFTAG_EXTRASAMPLES, 1, &alpha);
  }
}

// GeoTIFF arrays hold a handful of values and GDAL metadata a few KiB (the reader's bound).
constexpr size_t kMaxGeoValues = size_t(1) << 16;

// Writes one array tag when `values` holds what the tag does; says why not otherwise.
template <typename T>
bool setGeoArray(TIFF* tiff, uint32_t tag, const nlohmann::json& values, std::string* why) {
  if (!values.is_array() || values.empty() || values.size() > kMaxGeoValues) {
    *why = fmt::format("not an array of 1 to {} values", kMaxGeoValues);
    return false;
  }
  std::vector<T> data;
  data.reserve(values.size());
  for (const nlohmann::json& value : values) {
    if constexpr (std::is_same_v<T, uint16_t>) {
      if (!value.is_number_unsigned() || value.get<uint64_t>() > 0xFFFF) {
        *why = "holds a value that is not a 16-bit unsigned integer";
        return false;
      }
      data.push_back(uint16_t(value.get<uint64_t>()));
    } else {
      if (!value.is_number()) {
        *why = "holds a value that is not a number";
        return false;
      }
      data.push_back(value.get<double>());
    }
  }
  if (TIFFSetField(tiff, tag, uint32_t(data.size()), data.data()) == 1) return true;
  *why = "refused by libtiff";
  return false;
}

}  // namespace

// Goes on level 0's directory only, where GDAL and QGIS look. A bad entry (an edited or
// hostile archive) is left out with a warning rather than failing the export of good pixels.
void setGeoreferenceTags(TIFF* tiff, const std::string& georeference_json, ExportReport& report) {
  const nlohmann::json geo = nlohmann::json::parse(georeference_json, nullptr, false);
  if (!geo.is_object()) {
    report.warnings.push_back("georeference is not a JSON object; not written");
    return;
  }
  const auto skip = [&](const char* key, const std::string& why) {
    report.warnings.push_back(fmt::format("georeference.{} {}; not written", key, why));
  };
  struct ArrayTag {
    uint32_t tag;
    const char* key;
    bool shorts;
  };
  for (const ArrayTag& entry : {ArrayTag{kTagModelPixelScale, "model_pixel_scale", false},
                                ArrayTag{kTagModelTiepoint, "model_tiepoint", false},
                                ArrayTag{kTagModelTransformation, "model_transformation", false},
                                ArrayTag{kTagGeoKeyDirectory, "geo_key_directory", true},
                                ArrayTag{kTagGeoDoubleParams, "geo_double_params", false}}) {
    if (!geo.contains(entry.key)) continue;
    std::string why;
    const bool set = entry.shorts ? setGeoArray<uint16_t>(tiff, entry.tag, geo[entry.key], &why)
                                  : setGeoArray<double>(tiff, entry.tag, geo[entry.key], &why);
    if (set)
      report.georeferenced = true;
    else
      skip(entry.key, why);
  }
  struct TextTag {
    uint32_t tag;
    const char* key;
  };
  for (const TextTag& entry :
       {TextTag{kTagGeoAsciiParams, "geo_ascii_params"}, TextTag{kTagGdalNodata, "gdal_nodata"},
        TextTag{kTagGdalMetadata, "gdal_metadata"}}) {
    if (!geo.contains(entry.key)) continue;
    const nlohmann::json& value = geo[entry.key];
    if (!value.is_string() || value.get_ref<const std::string&>().size() > kMaxGeoValues ||
        value.get_ref<const std::string&>().find('\0') != std::string::npos) {
      skip(entry.key, "is not a text without NUL of at most 65536 bytes");
      continue;
    }
    if (TIFFSetField(tiff, entry.tag, value.get_ref<const std::string&>().c_str()) == 1)
      report.georeferenced = true;
    else
      skip(entry.key, "refused by libtiff");
  }
}

namespace {

// The tile's texels without the archive's border, tile_size square.
Image withoutBorder(const Image& stored, const ImageInfo& info) {
  if (info.border_px == 0) return stored;
  Image out(info.tile_size_px, info.tile_size_px, stored.channels, stored.sample_type);
  const size_t row_bytes = size_t(info.tile_size_px) * stored.texelBytes();
  for (uint32_t y = 0; y < info.tile_size_px; ++y)
    std::copy_n(stored.row(y + info.border_px) + size_t(info.border_px) * stored.texelBytes(),
                row_bytes, out.row(y));
  return out;
}

// One tile's bytes for the TIFF: either the payload as stored, already compressed as the
// directory says (written raw), or texels for libtiff to compress.
struct TiffTile {
  std::vector<uint8_t> bytes;
  bool compressed = false;  ///< `bytes` are compressed already (written raw)
  bool copied = false;      ///< `bytes` are the stored payload
};

Result<TiffTile> tileBytes(const Archive& archive, const ImageInfo& info, const TileId& tile,
                           const LevelPlan& plan, int quality) {
  TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(tile));
  std::vector<uint8_t> payload;
  if (entry.kind == TileKind::kEncoded) {
    TESSERA_ASSIGN_OR_RETURN(payload, archive.readPayload(tile, entry));
    const bool copy_jpeg = plan.encoding.copy_jpeg && entry.codec == Codec::kJpeg &&
                           (info.channels == 1 || jpegSampling(payload) == plan.sampling);
    const bool copy_zstd = plan.encoding.copy_zstd && entry.codec == Codec::kZstd &&
                           isWholeZstdFrame(payload, info.storedTileBytes());
    if (copy_jpeg || copy_zstd) return TiffTile{std::move(payload), true, true};
  }
  TESSERA_ASSIGN_OR_RETURN(Image stored, archive.decodeTile(tile, entry, payload));
  Image texels = withoutBorder(stored, info);
  if (!plan.encoding.copy_jpeg) return TiffTile{std::move(texels.texels), false, false};
  EncodeOptions options;
  options.quality = quality;
  options.chroma_subsampling = plan.sampling.horizontal == 2;
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> encoded,
                           encodeTile(Codec::kJpeg, texels.view(), options));
  return TiffTile{std::move(encoded), true, false};
}

Result<void> writeLevel(TIFF* tiff, const std::string& path, const Archive& archive,
                        const ExportOptions& options, uint32_t level, ExportReport& report,
                        uint64_t total) {
  const ImageInfo& info = archive.images()[options.image];
  TESSERA_ASSIGN_OR_RETURN(LevelPlan plan, planLevel(archive, info, options.image, level));
  setLevelTags(tiff, info, level, plan);
  if (level == 0) {
    if (const std::string geo = imageGeoreferenceJson(archive, options.image); !geo.empty())
      setGeoreferenceTags(tiff, geo, report);
  }
  for (uint32_t y = 0; y < info.tilesY(level); ++y) {
    for (uint32_t x = 0; x < info.tilesX(level); ++x) {
      const TileId tile{options.image, level, x, y};
      TESSERA_ASSIGN_OR_RETURN(TiffTile bytes,
                               tileBytes(archive, info, tile, plan, options.jpeg_quality));
      const uint32_t index =
          TIFFComputeTile(tiff, x * info.tile_size_px, y * info.tile_size_px, 0, 0);
      const tmsize_t written =
          bytes.compressed
              ? TIFFWriteRawTile(tiff, index, bytes.bytes.data(), tmsize_t(bytes.bytes.size()))
              : TIFFWriteEncodedTile(tiff, index, bytes.bytes.data(), tmsize_t(bytes.bytes.size()));
      if (written < 0)
        return fail(ErrorCode::kIo,
                    fmt::format("{}: writing {} failed", path, archive.tileName(tile)));
      report.tiles_copied += bytes.copied ? 1 : 0;
      ++report.tiles;
      if (options.on_progress) options.on_progress(report.tiles, total);
    }
  }
  if (!TIFFWriteDirectory(tiff))
    return fail(ErrorCode::kIo,
                fmt::format("{}: writing level {}'s directory failed", path, level));
  return {};
}

}  // namespace

Result<ExportReport> exportTiff(const Archive& archive, const std::string& out_path,
                                const ExportOptions& options) {
  const ImageInfo& info = archive.images()[options.image];
  uint64_t total = 0;
  for (uint32_t level = 0; level < info.level_count; ++level)
    total += uint64_t(info.tilesX(level)) * info.tilesY(level);
  ExportReport report;
  report.tile_format = chooseEncoding(info).name;
  registerGeoTiffTags();
  const auto write = [&](const std::string& partial) -> Result<void> {
    // Little-endian whatever the host: copied zstd payloads hold little-endian samples.
    TiffFile tiff(TIFFOpen(partial.c_str(), "w8l"));
    if (!tiff) return fail(ErrorCode::kIo, fmt::format("{}: cannot create", partial));
    for (uint32_t level = 0; level < info.level_count; ++level)
      TESSERA_TRY(writeLevel(tiff.get(), out_path, archive, options, level, report, total));
    TIFF* raw = tiff.release();
    // TIFFClose flushes; its failure (a full disk) is only visible through TIFFFlush.
    const bool flushed = TIFFFlush(raw) == 1;
    TIFFClose(raw);
    if (!flushed) return fail(ErrorCode::kIo, fmt::format("{}: flush failed", out_path));
    return {};
  };
  TESSERA_TRY(writeThroughPartialFile(out_path, write));
  std::error_code error;
  report.bytes = std::filesystem::file_size(out_path, error);
  return report;
}

}  // namespace tessera::detail
