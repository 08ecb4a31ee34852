// The TIFF export of u16 and f32 images (docs/export.md, "Pyramidal TIFF"): the tags a reader
// needs to take the samples as they are, stored zstd payloads copied or texels compressed by
// libtiff, every level read back through libtiff and through `tessera build` bit for bit (NaN
// payloads, infinities and -0 included), and the 8-bit targets refusing wide images by name.
#include <tiffio.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <ostream>
#include <span>

#include <gtest/gtest.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/build.h>

#include "builder/archive_writer.h"
#include "codecs/encode.h"
#include "export/export.h"
#include "format/checksum.h"
#include "support/test_images.h"
#include "support/wide_archive.h"

namespace tessera::detail {
namespace {

namespace fs = std::filesystem;

// 150 x 100 px in 64-px tiles: three levels (3x2, 2x1 and 1 tile), edge tiles on both sides.
constexpr uint32_t kWidth = 150, kHeight = 100, kTile = 64;

// Samples that an export could lose: every u16 bit pattern region, and for f32 a quiet NaN
// with a payload, a negative NaN, both infinities, -0, a subnormal and ordinary values.
double wideSample(SampleType type, uint32_t x, uint32_t y, uint32_t c) {
  if (type == SampleType::kU16) return double((x * 131 + y * 977 + c * 4099) % 65536);
  switch ((x * 7 + y * 13 + c * 3) % 17) {
    case 0: return std::bit_cast<double>(uint64_t{0x7FF8000020000000});  // f32 0x7FC00001
    case 1: return -std::numeric_limits<double>::quiet_NaN();
    case 2: return std::numeric_limits<double>::infinity();
    case 3: return -std::numeric_limits<double>::infinity();
    case 4: return -0.0;
    case 5: return 1e-42;
    default: return x * 0.37 - y * 1.5 + c * 1000.25;
  }
}

struct WideCase {
  SampleType type;
  uint32_t channels;
  Codec codec;
  uint32_t border_px;
  bool payloads_copied;  ///< zstd without border: every stored payload is a TIFF tile
  uint16_t predictor;    ///< what the directories must say
  uint16_t photometric;
  const char* name;
};

void PrintTo(const WideCase& wide, std::ostream* out) {
  *out << wide.name;
}

class WideTiffExport : public ::testing::TestWithParam<WideCase> {
 protected:
  void SetUp() override {
    dir_ = fmt::format("{}/wide-tiff-{}/", test::testTempDir(), GetParam().name);
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    const WideCase& wide = GetParam();
    archive_ = test::buildWideArchive(
        dir_ + "wide.tess", kWidth, kHeight, wide.channels, wide.type,
        [&](uint32_t x, uint32_t y, uint32_t c) { return wideSample(wide.type, x, y, c); }, kTile,
        wide.codec, wide.border_px);
    ASSERT_TRUE(archive_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string dir_;
  std::shared_ptr<Archive> archive_;
};

// The level's samples as the archive holds them, bytes in host (little-endian) order.
std::vector<uint8_t> levelBytes(const Archive& archive, uint32_t level) {
  const ImageInfo& info = archive.images()[0];
  Result<Image> region =
      archive.readRegion(0, level, {0, 0, info.levelWidthPx(level), info.levelHeightPx(level)});
  EXPECT_TRUE(region) << region.error().message;
  return region ? region->texels : std::vector<uint8_t>{};
}

// The current directory of `tiff`, read tile by tile through libtiff, holds `level` of the
// archive's image 0 byte for byte.
void expectDirectoryHoldsTheLevel(TIFF* tiff, const Archive& archive, uint32_t level) {
  const ImageInfo& info = archive.images()[0];
  const uint32_t texel_bytes = info.texelBytes();
  const uint32_t width = info.levelWidthPx(level), height = info.levelHeightPx(level);
  const std::vector<uint8_t> expected = levelBytes(archive, level);
  ASSERT_EQ(expected.size(), size_t(width) * height * texel_bytes);
  std::vector<uint8_t> tile(size_t(TIFFTileSize(tiff)));
  ASSERT_EQ(tile.size(), size_t(kTile) * kTile * texel_bytes);
  for (uint32_t ty = 0; ty < height; ty += kTile) {
    for (uint32_t tx = 0; tx < width; tx += kTile) {
      ASSERT_EQ(TIFFReadTile(tiff, tile.data(), tx, ty, 0, 0), tmsize_t(tile.size()))
          << tx << "," << ty;
      const size_t row_bytes = size_t(std::min(kTile, width - tx)) * texel_bytes;
      for (uint32_t y = ty; y < std::min(height, ty + kTile); ++y)
        ASSERT_EQ(std::memcmp(tile.data() + size_t(y - ty) * kTile * texel_bytes,
                              expected.data() + (size_t(y) * width + tx) * texel_bytes, row_bytes),
                  0)
            << "tile at " << tx << "," << ty << ", row " << y;
    }
  }
}

TEST_P(WideTiffExport, TagsSayWhatTheSamplesAreAndLibtiffReadsThemBitForBit) {
  const WideCase& wide = GetParam();
  ExportOptions options;
  options.format = ExportFormat::kTiff;
  const std::string out = dir_ + "wide.tif";
  Result<ExportReport> report = exportArchive(*archive_, out, options);
  ASSERT_TRUE(report) << report.error().message;
  const ImageInfo& info = archive_->images()[0];
  EXPECT_EQ(report->tiles, 6u + 2u + 1u);
  EXPECT_EQ(report->tile_format, "zstd");
  EXPECT_EQ(report->tiles_copied, wide.payloads_copied ? report->tiles : 0u);

  TIFF* tiff = TIFFOpen(out.c_str(), "r");
  ASSERT_NE(tiff, nullptr);
  uint32_t level = 0;
  do {
    ASSERT_LT(level, info.level_count);
    SCOPED_TRACE(fmt::format("level {}", level));
    uint16_t bits = 0, format = 0, photometric = 0, compression = 0, predictor = 0, samples = 0;
    uint16_t extra_count = 0;
    uint16_t* extra = nullptr;
    uint32_t width = 0, height = 0;
    TIFFGetField(tiff, TIFFTAG_IMAGEWIDTH, &width);
    TIFFGetField(tiff, TIFFTAG_IMAGELENGTH, &height);
    TIFFGetField(tiff, TIFFTAG_BITSPERSAMPLE, &bits);
    TIFFGetField(tiff, TIFFTAG_SAMPLEFORMAT, &format);
    TIFFGetField(tiff, TIFFTAG_PHOTOMETRIC, &photometric);
    TIFFGetField(tiff, TIFFTAG_COMPRESSION, &compression);
    TIFFGetFieldDefaulted(tiff, TIFFTAG_PREDICTOR, &predictor);
    TIFFGetField(tiff, TIFFTAG_SAMPLESPERPIXEL, &samples);
    TIFFGetFieldDefaulted(tiff, TIFFTAG_EXTRASAMPLES, &extra_count, &extra);
    EXPECT_EQ(width, info.levelWidthPx(level));
    EXPECT_EQ(height, info.levelHeightPx(level));
    EXPECT_EQ(bits, wide.type == SampleType::kF32 ? 32 : 16);
    EXPECT_EQ(format, wide.type == SampleType::kF32 ? SAMPLEFORMAT_IEEEFP : SAMPLEFORMAT_UINT);
    EXPECT_EQ(photometric, wide.photometric);
    EXPECT_EQ(compression, COMPRESSION_ZSTD);
    EXPECT_EQ(predictor, wide.predictor);
    EXPECT_EQ(samples, wide.channels);
    const bool alpha = wide.channels == 2 || wide.channels == 4;
    ASSERT_EQ(extra_count, alpha ? 1 : 0);
    if (alpha) {
      EXPECT_EQ(extra[0], EXTRASAMPLE_UNASSALPHA);
    }

    expectDirectoryHoldsTheLevel(tiff, *archive_, level);
    ++level;
  } while (TIFFReadDirectory(tiff));
  TIFFClose(tiff);
  EXPECT_EQ(level, info.level_count);
}

// The round trip: export, then `tessera build` from the TIFF, gives the same image,
// level for level and bit for bit.
TEST_P(WideTiffExport, BuildFromTheExportGivesBackEveryLevelBitForBit) {
  const WideCase& wide = GetParam();
  ExportOptions options;
  options.format = ExportFormat::kTiff;
  const std::string out = dir_ + "wide.tif";
  Result<ExportReport> report = exportArchive(*archive_, out, options);
  ASSERT_TRUE(report) << report.error().message;
  BuildOptions build;
  build.inputs = {out};
  build.output = dir_ + "again.tess";
  build.codec = wide.codec;
  build.tile_size_px = kTile;
  build.border_px = wide.border_px;
  build.threads = 2;
  Result<BuildReport> built = buildArchive(build);
  ASSERT_TRUE(built) << built.error().message;
  auto again = Archive::openFile(build.output);
  ASSERT_TRUE(again) << again.error().message;
  const ImageInfo& a = archive_->images()[0];
  const ImageInfo& b = (*again)->images()[0];
  EXPECT_EQ(b.sample_type, a.sample_type);
  EXPECT_EQ(b.channels, a.channels);
  ASSERT_EQ(b.width_px, a.width_px);
  ASSERT_EQ(b.height_px, a.height_px);
  ASSERT_EQ(b.level_count, a.level_count);
  for (uint32_t level = 0; level < a.level_count; ++level)
    EXPECT_TRUE(levelBytes(*archive_, level) == levelBytes(**again, level)) << "level " << level;
  if (wide.type != SampleType::kF32) return;
  // The values a float conversion or a filter would lose are there, and came back.
  const std::vector<uint8_t> base = levelBytes(**again, 0);
  std::vector<uint32_t> bits(base.size() / 4);
  std::memcpy(bits.data(), base.data(), base.size());
  for (uint32_t pattern : {0x7FC00001u, 0xFFC00000u, 0x7F800000u, 0xFF800000u, 0x80000000u})
    EXPECT_NE(std::count(bits.begin(), bits.end(), pattern), 0) << std::hex << pattern;
}

INSTANTIATE_TEST_SUITE_P(
    U16AndF32, WideTiffExport,
    ::testing::Values(WideCase{SampleType::kU16, 1, Codec::kZstd, 0, true, PREDICTOR_NONE,
                               PHOTOMETRIC_MINISBLACK, "u16_gray_zstd"},
                      WideCase{SampleType::kF32, 4, Codec::kZstd, 0, true, PREDICTOR_NONE,
                               PHOTOMETRIC_RGB, "f32_rgba_zstd"},
                      WideCase{SampleType::kU16, 2, Codec::kZdelta, 0, false, PREDICTOR_HORIZONTAL,
                               PHOTOMETRIC_MINISBLACK, "u16_gray_alpha_zdelta"},
                      WideCase{SampleType::kF32, 3, Codec::kZstd, 2, false, PREDICTOR_FLOATINGPOINT,
                               PHOTOMETRIC_RGB, "f32_rgb_zstd_border"}),
    [](const ::testing::TestParamInfo<WideCase>& param) { return std::string(param.param.name); });

// A zstd image whose tiles are not all zstd (payloads written by another build, or empty
// entries): the zstd ones are copied, the others decoded and compressed by libtiff in the same
// ZSTD directory, and libtiff reads every level back as the archive holds it.
TEST(WideTiffExportMixed, OtherCodecsAndEmptyTilesAmongCopiedOnesAreCompressedByLibtiff) {
  const std::string dir = test::testTempDir() + "/wide-tiff-mixed/";
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::shared_ptr<Archive> source = test::buildWideArchive(
      dir + "source.tess", kWidth, kHeight, 2, SampleType::kU16,
      [](uint32_t x, uint32_t y, uint32_t c) { return wideSample(SampleType::kU16, x, y, c); },
      kTile);
  ASSERT_TRUE(source);
  // The same tiles stored with zstd, raw, zdelta and as empty entries in turn.
  SpooledImage spooled{source->images()[0], {}};
  const ImageInfo& info = spooled.info;
  std::vector<std::vector<uint8_t>> payloads;
  uint32_t zstd_tiles = 0, turn = 0;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    spooled.entries.emplace_back();
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        SpoolEntry& entry = spooled.entries.back().emplace_back();
        const Codec codecs[] = {Codec::kZstd, Codec::kRaw, Codec::kZdelta};
        if (turn % 4 == 3) {
          ++turn;
          continue;  // empty
        }
        Result<Image> texels = source->readTile({0, level, x, y});
        ASSERT_TRUE(texels) << texels.error().message;
        entry.codec = codecs[turn++ % 4];
        Result<std::vector<uint8_t>> payload = encodeTile(entry.codec, texels->view(), {});
        ASSERT_TRUE(payload) << payload.error().message;
        entry.kind = TileKind::kEncoded;
        entry.length_bytes = uint32_t(payload->size());
        entry.checksum = checksum64(*payload);
        entry.spool_offset = payloads.size();
        payloads.push_back(std::move(*payload));
        zstd_tiles += entry.codec == Codec::kZstd ? 1 : 0;
      }
  }
  const std::string mixed_path = dir + "mixed.tess";
  {
    Result<TempFile> out = TempFile::create(mixed_path);
    ASSERT_TRUE(out) << out.error().message;
    auto fetch = [&](const TileId&, const SpoolEntry& entry, std::span<uint8_t> bytes) {
      std::copy(payloads[entry.spool_offset].begin(), payloads[entry.spool_offset].end(),
                bytes.begin());
      return Result<void>{};
    };
    Result<WrittenArchive> written =
        writeArchive(fetch, std::span<const SpooledImage>(&spooled, 1), TileOrder::kRowMajor,
                     nlohmann::json::parse(source->metadataJson()), *out);
    ASSERT_TRUE(written) << written.error().message;
    ASSERT_TRUE(out->commit());
  }
  auto mixed = Archive::openFile(mixed_path);
  ASSERT_TRUE(mixed) << mixed.error().message;
  ExportOptions options;
  options.format = ExportFormat::kTiff;
  Result<ExportReport> report = exportArchive(**mixed, dir + "mixed.tif", options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tiles, 9u);
  EXPECT_EQ(report->tiles_copied, zstd_tiles);
  EXPECT_GT(zstd_tiles, 0u);
  EXPECT_LT(zstd_tiles, report->tiles);
  TIFF* tiff = TIFFOpen((dir + "mixed.tif").c_str(), "r");
  ASSERT_NE(tiff, nullptr);
  uint32_t level = 0;
  do {
    SCOPED_TRACE(fmt::format("level {}", level));
    ASSERT_LT(level, info.level_count);
    expectDirectoryHoldsTheLevel(tiff, **mixed, level++);
  } while (TIFFReadDirectory(tiff));
  TIFFClose(tiff);
  EXPECT_EQ(level, info.level_count);
  fs::remove_all(dir);
}

// Deep Zoom, PMTiles and MBTiles tiles are 8-bit pictures: a wide image is refused naming the
// image, its sample type and the target that does take it, and nothing is written.
TEST(WideExport, EightBitTargetsNameTheSampleTypeAndPointAtTiff) {
  const std::string dir = test::testTempDir() + "/wide-refused/";
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    std::shared_ptr<Archive> archive = test::buildWideArchive(
        dir + "wide.tess", 40, 30, 1, type, [](uint32_t x, uint32_t, uint32_t) { return x; });
    ASSERT_TRUE(archive);
    for (ExportFormat format :
         {ExportFormat::kDeepZoom, ExportFormat::kPmtiles, ExportFormat::kMbtiles}) {
      ExportOptions options;
      options.format = format;
      const std::string out = dir + (format == ExportFormat::kDeepZoom ? "out.dzi" : "out.tiles");
      Result<ExportReport> report = exportArchive(*archive, out, options);
      ASSERT_FALSE(report);
      EXPECT_EQ(report.error().code, ErrorCode::kUnsupported);
      const std::string& message = report.error().message;
      EXPECT_NE(message.find("image 0"), std::string::npos) << message;
      EXPECT_NE(message.find(fmt::format("{} samples", sampleTypeName(type))), std::string::npos)
          << message;
      EXPECT_NE(message.find(exportFormatName(format)), std::string::npos) << message;
      EXPECT_NE(message.find("--to tiff"), std::string::npos) << message;
      EXPECT_FALSE(fs::exists(out));
      EXPECT_FALSE(fs::exists(dir + "out_files"));
    }
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera::detail
