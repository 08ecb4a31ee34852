// Importing a u16 or f32 pyramidal TIFF with ZSTD tiles into a zstd archive (docs/import.md):
// the tiles `tessera export --to tiff` copied out of a zstd archive come back as stored, byte
// for byte; tiles the archive could not keep as they are (libtiff's frames without a content
// size, zero-padded edge tiles, a predictor, another tile size) are decoded and encoded, and
// every level stays exact.
#include <tiffio.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <ostream>

#include <gtest/gtest.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/build.h>

#include "codecs/encode.h"
#include "export/export.h"
#include "support/test_images.h"
#include "support/wide_archive.h"

namespace tessera::detail {
namespace {

namespace fs = std::filesystem;

// 150 x 100 px in 64-px tiles: levels of 3x2, 2x1 and 1 tile, edge tiles on both sides.
constexpr uint32_t kWidth = 150, kHeight = 100, kTile = 64;
constexpr uint32_t kTilesBelowCoarsest = 6 + 2;  // the coarsest level is always computed

double sample(SampleType type, uint32_t x, uint32_t y, uint32_t c) {
  if (type == SampleType::kU16) return double((x * 131 + y * 977 + c * 4099) % 65536);
  return x * 0.37 - y * 1.5 + c * 1000.25 + ((x ^ y) % 5 == 0 ? 1e-42 : 0.0);
}

struct WideImage {
  SampleType type;
  uint32_t channels;
  const char* name;
};

void PrintTo(const WideImage& image, std::ostream* out) {
  *out << image.name;
}

// The level's samples, packed, host (little-endian) order.
std::vector<uint8_t> levelBytes(const Archive& archive, uint32_t level) {
  const ImageInfo& info = archive.images()[0];
  Result<Image> region =
      archive.readRegion(0, level, {0, 0, info.levelWidthPx(level), info.levelHeightPx(level)});
  EXPECT_TRUE(region) << region.error().message;
  return region ? region->texels : std::vector<uint8_t>{};
}

// How a hand-written ZSTD pyramid differs from the export's.
struct ZstdTiffLayout {
  uint16_t predictor = PREDICTOR_NONE;
  bool own_frames = true;     ///< frames from the zstd codec written raw, else libtiff's encoder
  bool zero_padding = false;  ///< edge tiles padded with zeros, else by edge replication
  bool sparse_tile = false;   ///< level 0's tile (1,0) left out (a sparse tile, read as zeros)
};

// Writes the archive's image as a pyramidal little-endian BigTIFF of kTile ZSTD tiles.
void writeZstdPyramid(const Archive& archive, const std::string& path,
                      const ZstdTiffLayout& layout) {
  const ImageInfo& info = archive.images()[0];
  const uint32_t texel = info.texelBytes();
  TIFF* tiff = TIFFOpen(path.c_str(), "w8l");
  ASSERT_NE(tiff, nullptr);
  for (uint32_t level = 0; level < info.level_count; ++level) {
    const uint32_t width = info.levelWidthPx(level), height = info.levelHeightPx(level);
    TIFFSetField(tiff, TIFFTAG_SUBFILETYPE, level == 0 ? 0 : FILETYPE_REDUCEDIMAGE);
    TIFFSetField(tiff, TIFFTAG_IMAGEWIDTH, width);
    TIFFSetField(tiff, TIFFTAG_IMAGELENGTH, height);
    TIFFSetField(tiff, TIFFTAG_TILEWIDTH, kTile);
    TIFFSetField(tiff, TIFFTAG_TILELENGTH, kTile);
    TIFFSetField(tiff, TIFFTAG_BITSPERSAMPLE, 8 * sampleBytes(info.sample_type));
    TIFFSetField(tiff, TIFFTAG_SAMPLEFORMAT,
                 info.sample_type == SampleType::kF32 ? SAMPLEFORMAT_IEEEFP : SAMPLEFORMAT_UINT);
    TIFFSetField(tiff, TIFFTAG_SAMPLESPERPIXEL, info.channels);
    TIFFSetField(tiff, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(tiff, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
    if (info.channels == 2) {
      const uint16_t alpha = EXTRASAMPLE_UNASSALPHA;
      TIFFSetField(tiff, TIFFTAG_EXTRASAMPLES, 1, &alpha);
    }
    TIFFSetField(tiff, TIFFTAG_COMPRESSION, COMPRESSION_ZSTD);
    TIFFSetField(tiff, TIFFTAG_PREDICTOR, layout.predictor);
    const std::vector<uint8_t> texels = levelBytes(archive, level);
    for (uint32_t ty = 0; ty < info.tilesY(level); ++ty)
      for (uint32_t tx = 0; tx < info.tilesX(level); ++tx) {
        Image tile(kTile, kTile, info.channels, info.sample_type);
        for (uint32_t y = 0; y < kTile; ++y)
          for (uint32_t x = 0; x < kTile; ++x) {
            const uint32_t sx = tx * kTile + x, sy = ty * kTile + y;
            if (layout.zero_padding && (sx >= width || sy >= height)) continue;
            std::memcpy(
                tile.row(y) + size_t(x) * texel,
                texels.data() +
                    (size_t(std::min(sy, height - 1)) * width + std::min(sx, width - 1)) * texel,
                texel);
          }
        if (layout.sparse_tile && level == 0 && tx == 1 && ty == 0) continue;
        const uint32_t index = TIFFComputeTile(tiff, tx * kTile, ty * kTile, 0, 0);
        if (layout.own_frames) {
          Result<std::vector<uint8_t>> frame = encodeTile(Codec::kZstd, tile.view(), {});
          ASSERT_TRUE(frame) << frame.error().message;
          ASSERT_GE(TIFFWriteRawTile(tiff, index, frame->data(), tmsize_t(frame->size())), 0);
        } else {
          ASSERT_GE(
              TIFFWriteEncodedTile(tiff, index, tile.texels.data(), tmsize_t(tile.texels.size())),
              0);
        }
      }
    ASSERT_TRUE(TIFFWriteDirectory(tiff));
  }
  TIFFClose(tiff);
}

class WideTiffImport : public ::testing::TestWithParam<WideImage> {
 protected:
  void SetUp() override {
    dir_ = fmt::format("{}/wide-tiff-import-{}/", test::testTempDir(), GetParam().name);
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    const WideImage& image = GetParam();
    original_ = test::buildWideArchive(
        dir_ + "original.tess", kWidth, kHeight, image.channels, image.type,
        [&](uint32_t x, uint32_t y, uint32_t c) { return sample(image.type, x, y, c); }, kTile);
    ASSERT_TRUE(original_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string exportTiff() {
    ExportOptions options;
    options.format = ExportFormat::kTiff;
    const std::string out = dir_ + "exported.tif";
    Result<ExportReport> report = exportArchive(*original_, out, options);
    EXPECT_TRUE(report) << report.error().message;
    return out;
  }

  struct Imported {
    BuildReport report;
    std::shared_ptr<Archive> archive;
    nlohmann::json copied_levels;  ///< the image metadata's import.copied_levels
  };

  Imported import(const std::string& tif, uint32_t tile_size_px = kTile) {
    BuildOptions build;
    build.inputs = {tif};
    build.output = dir_ + "imported.tess";
    build.codec = Codec::kZstd;
    build.tile_size_px = tile_size_px;
    build.threads = 2;
    Imported out;
    Result<BuildReport> built = buildArchive(build);
    EXPECT_TRUE(built) << built.error().message;
    if (!built) return out;
    out.report = *built;
    auto archive = Archive::openFile(build.output);
    EXPECT_TRUE(archive) << archive.error().message;
    if (!archive) return out;
    out.archive = std::move(*archive);
    const nlohmann::json meta = nlohmann::json::parse(out.archive->metadataJson());
    out.copied_levels = meta["images"][0]["import"]["copied_levels"];
    return out;
  }

  // Every level holds the original's samples, and, when the tile sizes agree, every tile the
  // original's payload byte for byte (the zstd encoder is deterministic).
  void expectSameAsOriginal(const Archive& imported, bool same_payloads) {
    const ImageInfo& a = original_->images()[0];
    const ImageInfo& b = imported.images()[0];
    ASSERT_EQ(b.sample_type, a.sample_type);
    ASSERT_EQ(b.channels, a.channels);
    for (uint32_t level = 0; level < std::min(a.level_count, b.level_count); ++level)
      EXPECT_TRUE(levelBytes(*original_, level) == levelBytes(imported, level))
          << "level " << level;
    if (!same_payloads) return;
    ASSERT_EQ(b.level_count, a.level_count);
    for (uint32_t level = 0; level < a.level_count; ++level)
      for (uint32_t y = 0; y < a.tilesY(level); ++y)
        for (uint32_t x = 0; x < a.tilesX(level); ++x) {
          const TileId tile{0, level, x, y};
          Result<TileEntry> ea = original_->tileEntry(tile);
          Result<TileEntry> eb = imported.tileEntry(tile);
          ASSERT_TRUE(ea && eb);
          EXPECT_EQ(eb->codec, Codec::kZstd);
          Result<std::vector<uint8_t>> pa = original_->readPayload(tile, *ea);
          Result<std::vector<uint8_t>> pb = imported.readPayload(tile, *eb);
          ASSERT_TRUE(pa && pb);
          EXPECT_TRUE(*pa == *pb) << imported.tileName(tile);
        }
  }

  std::string dir_;
  std::shared_ptr<Archive> original_;
};

TEST_P(WideTiffImport, ExportedZstdTilesAreCopiedBackAsStored) {
  Imported imported = import(exportTiff());
  ASSERT_TRUE(imported.archive);
  EXPECT_EQ(imported.report.tiles_copied, kTilesBelowCoarsest);
  EXPECT_EQ(imported.report.tiles_encoded, 1u);
  EXPECT_EQ(imported.copied_levels, nlohmann::json::array({0, 1}));
  expectSameAsOriginal(*imported.archive, /*same_payloads=*/true);
}

TEST_P(WideTiffImport, ZeroPaddedEdgeTilesAreEncodedAndInteriorTilesCopied) {
  writeZstdPyramid(*original_, dir_ + "zeros.tif", {.zero_padding = true});
  Imported imported = import(dir_ + "zeros.tif");
  ASSERT_TRUE(imported.archive);
  // Level 0's two tiles left of the right edge and above the bottom one are whole; level 1
  // (75 x 50 px) has none.
  EXPECT_EQ(imported.report.tiles_copied, 2u);
  EXPECT_EQ(imported.report.tiles_encoded, 9u - 2u);
  expectSameAsOriginal(*imported.archive, /*same_payloads=*/true);
}

// A tile the file leaves out reads as zeros, as libtiff reads it, in the image's sample type.
TEST_P(WideTiffImport, SparseTileIsZerosAndTheOthersAreCopied) {
  writeZstdPyramid(*original_, dir_ + "sparse.tif", {.sparse_tile = true});
  Imported imported = import(dir_ + "sparse.tif");
  ASSERT_TRUE(imported.archive);
  EXPECT_EQ(imported.report.tiles_copied, kTilesBelowCoarsest - 1);
  const ImageInfo& info = original_->images()[0];
  const uint32_t texel = info.texelBytes();
  std::vector<uint8_t> expected = levelBytes(*original_, 0);
  for (uint32_t y = 0; y < kTile; ++y)
    std::fill_n(expected.begin() + (size_t(y) * kWidth + kTile) * texel, size_t(kTile) * texel, 0);
  EXPECT_TRUE(levelBytes(*imported.archive, 0) == expected);
  for (uint32_t level = 1; level < info.level_count; ++level)
    EXPECT_TRUE(levelBytes(*original_, level) == levelBytes(*imported.archive, level))
        << "level " << level;
}

TEST_P(WideTiffImport, LibtiffFramesWithoutContentSizeAreDecodedAndEncoded) {
  writeZstdPyramid(*original_, dir_ + "libtiff.tif", {.own_frames = false});
  Imported imported = import(dir_ + "libtiff.tif");
  ASSERT_TRUE(imported.archive);
  // The levels are planned as copies; no tile's frame can be kept.
  EXPECT_EQ(imported.copied_levels, nlohmann::json::array({0, 1}));
  EXPECT_EQ(imported.report.tiles_copied, 0u);
  expectSameAsOriginal(*imported.archive, /*same_payloads=*/true);
}

TEST_P(WideTiffImport, PredictorOrOtherTileSizeIsComputedFromTheDecodedLevels) {
  writeZstdPyramid(*original_, dir_ + "predictor.tif",
                   {.predictor = PREDICTOR_HORIZONTAL, .own_frames = false});
  Imported predicted = import(dir_ + "predictor.tif");
  ASSERT_TRUE(predicted.archive);
  EXPECT_EQ(predicted.copied_levels, nlohmann::json::array());
  EXPECT_EQ(predicted.report.tiles_copied, 0u);
  expectSameAsOriginal(*predicted.archive, /*same_payloads=*/true);

  Imported resized = import(exportTiff(), 2 * kTile);
  ASSERT_TRUE(resized.archive);
  EXPECT_EQ(resized.copied_levels, nlohmann::json::array());
  EXPECT_EQ(resized.report.tiles_copied, 0u);
  expectSameAsOriginal(*resized.archive, /*same_payloads=*/false);
}

INSTANTIATE_TEST_SUITE_P(U16AndF32, WideTiffImport,
                         ::testing::Values(WideImage{SampleType::kU16, 1, "u16_gray"},
                                           WideImage{SampleType::kF32, 2, "f32_gray_alpha"}),
                         [](const ::testing::TestParamInfo<WideImage>& param) {
                           return std::string(param.param.name);
                         });

}  // namespace
}  // namespace tessera::detail
