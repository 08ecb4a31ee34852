// Importing pyramids other tools wrote (docs/import.md): pyramidal TIFFs from vips and GDAL,
// Deep Zoom folders, a generic tiled TIFF through OpenSlide, Tessera's own exports read back,
// and the inputs an import must refuse. Sources are generated; each test that needs a tool
// skips, saying so, where it is not installed (scripts/install-deps.sh installs them).
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>
#include <fmt/format.h>
#include <tiffio.h>

#include <tessera/archive.h>
#include <tessera/build.h>

#include "builder/band_reader.h"
#include "builder/pyramid_source.h"
#include "export/export.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

namespace fs = std::filesystem;

bool onPath(const std::string& tool) {
  return std::system(("command -v " + tool + " >/dev/null 2>&1").c_str()) == 0;
}

void run(const std::string& command) {
  ASSERT_EQ(std::system((command + " >/dev/null 2>&1").c_str()), 0) << command;
}

class PyramidImport : public ::testing::Test {
 protected:
  // A 1024 x 768 RGB source: its levels halve exactly, so every level the tools write has the
  // archive's size, and the coarsest (256 x 192) is one tile.
  void SetUp() override {
    dir_ = test::testTempDir() + "/pyramid-import-" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name() + "/";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    test::TiffSpec spec{.width_px = kWidth, .height_px = kHeight, .samples = 3};
    ASSERT_EQ(test::writeTiff(dir_ + "flat.tif", spec, test::makeTestPixels(kWidth, kHeight, 3, 5)),
              "");
  }

  // Writes flat.tif as a JPEG-tiled vips pyramid `name` (tiles `tile_px` square) with `extra`
  // tiffsave options, and returns its path.
  std::string vipsPyramid(const std::string& name, uint32_t tile_px = 256,
                          const std::string& extra = "") {
    run(
        fmt::format("vips tiffsave {0}flat.tif {0}{1} --tile --pyramid --compression jpeg "
                    "--tile-width {2} --tile-height {2} {3}",
                    dir_, name, tile_px, extra));
    return dir_ + name;
  }

  Result<BuildReport> build(const std::string& input, const std::string& output) {
    BuildOptions options;
    options.inputs = {input};
    options.output = dir_ + output;
    options.threads = 2;
    return buildArchive(options);
  }

  // How far each archive level is from the same level decoded from `level_of` (a reader of the
  // source's level, or null when the source has none of that size).
  struct Difference {
    int max = 0;
    double mean = 0;  ///< of the level that differs most on average
  };
  static Difference levelDifference(
      const Archive& archive, const std::function<std::unique_ptr<BandReader>(uint32_t)>& level_of,
      uint32_t* levels_compared) {
    const ImageInfo& info = archive.images()[0];
    Difference worst;
    for (uint32_t l = 0; l < info.level_count; ++l) {
      std::unique_ptr<BandReader> reader = level_of(l);
      if (!reader) continue;
      EXPECT_EQ(reader->info().width_px, info.levelWidthPx(l));
      EXPECT_EQ(reader->info().height_px, info.levelHeightPx(l));
      std::vector<uint8_t> rows(size_t(info.levelWidthPx(l)) * info.levelHeightPx(l) * 3);
      EXPECT_TRUE(reader->readRows(info.levelHeightPx(l), rows));
      auto region = archive.readRegion(0, l, {0, 0, info.levelWidthPx(l), info.levelHeightPx(l)});
      EXPECT_TRUE(region) << region.error().message;
      if (!region) return {255, 255};
      uint64_t sum = 0;
      for (size_t i = 0; i < rows.size(); ++i) {
        const int delta = std::abs(int(rows[i]) - int(region->texels[i]));
        worst.max = std::max(worst.max, delta);
        sum += delta;
      }
      worst.mean = std::max(worst.mean, double(sum) / rows.size());
      ++*levels_compared;
    }
    return worst;
  }

  // Imports `tif` and checks every level against libtiff's own decoding of the same level.
  void expectTiffImportMatches(const std::string& tif, bool expect_copies) {
    Result<BuildReport> report = build(tif, "imported.tess");
    ASSERT_TRUE(report) << report.error().message;
    auto archive = Archive::openFile(dir_ + "imported.tess");
    ASSERT_TRUE(archive) << archive.error().message;
    const ImageInfo& info = (*archive)->images()[0];
    ASSERT_EQ(info.level_count, 3u);
    if (expect_copies) {
      // Levels 0 (4x3 tiles) and 1 (2x2) copied; the single coarsest tile computed.
      EXPECT_EQ(report->tiles_copied, 12u + 4u);
      EXPECT_EQ(report->tiles_encoded, 1u);
    }
    auto source = openTiffPyramid(tif);
    ASSERT_TRUE(source && *source) << (source ? "not a pyramid" : source.error().message);
    // The source's level of an archive level's size, or null; without the coarsest when asked.
    auto level_of = [&](bool coarsest) {
      return [&, coarsest](uint32_t level) -> std::unique_ptr<BandReader> {
        if (!coarsest && level + 1 == info.level_count) return nullptr;
        for (uint32_t s = 0; s < (*source)->levels().size(); ++s) {
          if ((*source)->levels()[s].width_px != info.levelWidthPx(level)) continue;
          auto reader = (*source)->openLevel(s);
          return reader ? std::move(*reader) : nullptr;
        }
        return nullptr;
      };
    };
    uint32_t compared = 0;
    // Copied levels hold the source's own JPEG streams, decoded by libjpeg-turbo through
    // libtiff on one side and TurboJPEG on the other (accurate DCT, fancy upsampling both).
    EXPECT_EQ(levelDifference(**archive, level_of(false), &compared).max, 0);
    EXPECT_EQ(compared, 2u);
    // The coarsest level is computed from the level above it (a box filter, where the tools
    // use their own) and encoded again: close on average, a JPEG's error at worst.
    compared = 0;
    EXPECT_LE(levelDifference(**archive, level_of(true), &compared).mean, kComputedMeanLimit);
    EXPECT_EQ(compared, 3u);
  }

  static constexpr uint32_t kWidth = 1024, kHeight = 768;
  // Mean difference per sample of a level computed again and encoded at quality 85.
  static constexpr double kComputedMeanLimit = 3.0;
  std::string dir_;
};

TEST_F(PyramidImport, VipsPyramidCopiesMatchingTilesAndEqualsTheSourceLevels) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  vipsPyramid("vips.tif");
  expectTiffImportMatches(dir_ + "vips.tif", true);
}

TEST_F(PyramidImport, VipsSubIfdPyramidIsImported) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  vipsPyramid("subifd.tif", 256, "--subifd --bigtiff");
  expectTiffImportMatches(dir_ + "subifd.tif", true);
}

// Wide pyramids: vips writes float pyramids whose overviews lack SampleFormat (they inherit the
// base's), and no level of a u16 or f32 image may become a uniform entry. The base level must
// come through bit-exact, as from the same image stored flat.
TEST_F(PyramidImport, WidePyramidsKeepTheirSamplesExactly) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  run(fmt::format("vips gaussnoise {0}noise.v 600 500", dir_));
  run(fmt::format("vips black {0}black.v 600 500", dir_));
  for (const char* type : {"float", "ushort"}) {
    for (const char* content : {"noise", "black"}) {
      SCOPED_TRACE(fmt::format("{} {}", type, content));
      run(fmt::format("vips cast {0}{1}.v {0}cast.v {2}", dir_, content, type));
      run(
          fmt::format("vips tiffsave {0}cast.v {0}pyr.tif --tile --pyramid --tile-width 256 "
                      "--tile-height 256 --compression deflate",
                      dir_));
      run(fmt::format("vips tiffsave {0}cast.v {0}flat16.tif", dir_));
      BuildOptions options;
      options.codec = Codec::kZstd;
      options.threads = 2;
      options.tile_size_px = 256;
      for (const char* name : {"pyr", "flat16"}) {
        options.inputs = {dir_ + name + ".tif"};
        options.output = dir_ + name + ".tess";
        Result<BuildReport> report = buildArchive(options);
        ASSERT_TRUE(report) << report.error().message;
      }
      auto imported = Archive::openFile(dir_ + "pyr.tess");
      auto flat = Archive::openFile(dir_ + "flat16.tess");
      ASSERT_TRUE(imported && flat);
      EXPECT_TRUE((*imported)->verify(/*decode=*/true).ok());
      const ImageInfo& info = (*imported)->images()[0];
      EXPECT_EQ(info.sample_type,
                type == std::string("float") ? SampleType::kF32 : SampleType::kU16);
      for (uint32_t y = 0; y < info.tilesY(0); ++y)
        for (uint32_t x = 0; x < info.tilesX(0); ++x) {
          auto a = (*imported)->readTile({0, 0, x, y});
          auto b = (*flat)->readTile({0, 0, x, y});
          ASSERT_TRUE(a && b) << "tile " << x << "," << y;
          EXPECT_EQ(a->texels, b->texels) << "tile " << x << "," << y;
        }
    }
  }
}

TEST_F(PyramidImport, CogFromGdalCopiesMatchingTiles) {
  if (!onPath("gdal_translate")) GTEST_SKIP() << "gdal_translate not installed (Debian: gdal-bin)";
  run(
      fmt::format("gdal_translate -q -of COG -co COMPRESS=JPEG -co BLOCKSIZE=256 "
                  "-co BIGTIFF=YES {0}flat.tif {0}cog.tif",
                  dir_));
  expectTiffImportMatches(dir_ + "cog.tif", true);
}

TEST_F(PyramidImport, OtherTileSizeIsReencodedLevelByLevel) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  vipsPyramid("t128.tif", 128);
  Result<BuildReport> report = build(dir_ + "t128.tif", "t128.tess");
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tiles_copied, 0u);
  EXPECT_EQ(report->tiles_encoded, 12u + 4u + 1u);
}

TEST_F(PyramidImport, SplicedTablesDecodeAsLibtiffDecodesTheTile) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  vipsPyramid("vips.tif");
  auto source = openTiffPyramid(dir_ + "vips.tif");
  ASSERT_TRUE(source && *source);
  auto tile = (*source)->readTile(0, 1, 1);
  ASSERT_TRUE(tile) << tile.error().message;
  ASSERT_FALSE(tile->jpeg.empty());
  EXPECT_TRUE(checkJpegTile(tile->jpeg, 256, 3, "tile"));
  // The abbreviated stream alone has no tables; spliced, it is one whole JPEG.
  EXPECT_FALSE(completeTiffJpeg(std::vector<uint8_t>{0xFF, 0xD8, 0xFF}, tile->jpeg));
  EXPECT_FALSE(completeTiffJpeg({}, std::vector<uint8_t>{1, 2, 3, 4}));
}

TEST_F(PyramidImport, DeepZoomFolderIsImported) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  run(fmt::format("vips dzsave {0}flat.tif {0}dz --overlap 0 --tile-size 256 --suffix .jpg", dir_));
  Result<BuildReport> report = build(dir_ + "dz.dzi", "dz.tess");
  ASSERT_TRUE(report) << report.error().message;
  // Level 0 (4x3 whole tiles) and level 1's top row are copied; Deep Zoom crops level 1's
  // bottom row (384 px high), so those tiles and the coarsest level are encoded.
  EXPECT_EQ(report->tiles_copied, 12u + 2u);
  auto archive = Archive::openFile(dir_ + "dz.tess");
  ASSERT_TRUE(archive);
  auto source = openDeepZoom(dir_ + "dz.dzi");
  ASSERT_TRUE(source) << source.error().message;
  uint32_t compared = 0;
  const Difference worst = levelDifference(
      **archive,
      [&](uint32_t level) -> std::unique_ptr<BandReader> {
        auto reader = (*source)->openLevel(level);
        return reader ? std::move(*reader) : nullptr;
      },
      &compared);
  EXPECT_EQ(compared, 3u);
  EXPECT_LE(worst.mean, kComputedMeanLimit);
}

TEST_F(PyramidImport, DeepZoomWithAMissingTileNamesTheTile) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  run(fmt::format("vips dzsave {0}flat.tif {0}dz --overlap 0 --tile-size 256 --suffix .jpg", dir_));
  const std::string missing = dir_ + "dz_files/10/2_1.jpg";
  ASSERT_TRUE(fs::remove(missing));
  Result<BuildReport> report = build(dir_ + "dz.dzi", "dz.tess");
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find(missing), std::string::npos) << report.error().message;
  EXPECT_FALSE(fs::exists(dir_ + "dz.tess"));
}

TEST_F(PyramidImport, DeepZoomWithASixteenBitTileNamesTheTile) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  run(fmt::format("vips dzsave {0}flat.tif {0}dz --overlap 0 --tile-size 256 --suffix .png", dir_));
  for (const char* name : {"10/0_0.png", "10/3_2.png"}) {
    SCOPED_TRACE(name);
    const std::string tile = dir_ + "dz_files/" + name;
    const std::vector<uint8_t> original = test::readFileBytes(tile);
    auto reader = openBandReader(tile);
    ASSERT_TRUE(reader) << reader.error().message;
    test::PngSpec spec;
    spec.width_px = (*reader)->info().width_px;
    spec.height_px = (*reader)->info().height_px;
    spec.bit_depth = 16;
    ASSERT_EQ(test::writePng(tile, spec,
                             std::vector<uint8_t>(size_t(spec.width_px) * spec.height_px * 3, 40)),
              "");
    Result<BuildReport> report = build(dir_ + "dz.dzi", "dz.tess");
    ASSERT_FALSE(report);
    EXPECT_NE(report.error().message.find(tile + ": a Deep Zoom tile with u16 samples"),
              std::string::npos)
        << report.error().message;
    EXPECT_FALSE(fs::exists(dir_ + "dz.tess"));
    test::writeFileBytes(tile, original);
  }
}

// Two directories whose reduced level has another aspect: a label image, not a level.
TEST_F(PyramidImport, PyramidWhoseLevelsDisagreeIsRefused) {
  const std::string path = dir_ + "disagree.tif";
  TIFF* tif = TIFFOpen(path.c_str(), "w");
  ASSERT_NE(tif, nullptr);
  const std::pair<uint32_t, uint32_t> sizes[] = {{512, 512}, {256, 64}};
  for (size_t d = 0; d < 2; ++d) {
    TIFFSetField(tif, TIFFTAG_SUBFILETYPE, d == 0 ? 0 : FILETYPE_REDUCEDIMAGE);
    TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, sizes[d].first);
    TIFFSetField(tif, TIFFTAG_IMAGELENGTH, sizes[d].second);
    TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, 8);
    TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1);
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
    TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, sizes[d].second);
    std::vector<uint8_t> row(sizes[d].first, 100);
    for (uint32_t y = 0; y < sizes[d].second; ++y) TIFFWriteScanline(tif, row.data(), y, 0);
    TIFFWriteDirectory(tif);
  }
  TIFFClose(tif);
  Result<BuildReport> report = build(path, "disagree.tess");
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find(path), std::string::npos) << report.error().message;
  EXPECT_NE(report.error().message.find("256x64"), std::string::npos) << report.error().message;
}

TEST_F(PyramidImport, FileOpenSlideCannotReadIsRefusedNamingIt) {
  const std::string path = dir_ + "broken.svs";
  FILE* file = std::fopen(path.c_str(), "wb");
  ASSERT_NE(file, nullptr);
  std::fputs("not a slide at all", file);
  std::fclose(file);
  Result<BuildReport> report = build(path, "broken.tess");
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find(path), std::string::npos) << report.error().message;
}

TEST_F(PyramidImport, GenericTiledTiffThroughOpenSlide) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  vipsPyramid("slide.tif");
  auto slide = openSlide(dir_ + "slide.tif");
  if (!slide && slide.error().code == ErrorCode::kUnsupported)
    GTEST_SKIP() << slide.error().message;
  Result<BuildReport> report = build("openslide:" + dir_ + "slide.tif", "slide.tess");
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tiles_copied, 12u + 4u);  // generic-tiff: raw tiles through libtiff
  auto archive = Archive::openFile(dir_ + "slide.tess");
  ASSERT_TRUE(archive);
  uint32_t compared = 0;
  const Difference worst = levelDifference(
      **archive,
      [&](uint32_t level) -> std::unique_ptr<BandReader> {
        if (level >= (*slide)->levels().size()) return nullptr;
        auto reader = (*slide)->openLevel(level);
        return reader ? std::move(*reader) : nullptr;
      },
      &compared);
  EXPECT_EQ(compared, 3u);
  EXPECT_LE(worst.mean, kComputedMeanLimit);
}

TEST_F(PyramidImport, ExportToTiffThenImportKeepsPixelsAndLevels) {
  Result<BuildReport> original = build(dir_ + "flat.tif", "original.tess");
  ASSERT_TRUE(original) << original.error().message;
  auto archive = Archive::openFile(dir_ + "original.tess");
  ASSERT_TRUE(archive);
  for (ExportFormat format : {ExportFormat::kTiff, ExportFormat::kDeepZoom}) {
    const std::string exported = dir_ + (format == ExportFormat::kTiff ? "out.tif" : "out.dzi");
    ExportOptions options;
    options.format = format;
    auto written = exportArchive(**archive, exported, options);
    ASSERT_TRUE(written) << written.error().message;
    Result<BuildReport> again = build(exported, "again.tess");
    ASSERT_TRUE(again) << again.error().message;
    EXPECT_GE(again->tiles_copied, 12u) << exported;
    auto imported = Archive::openFile(dir_ + "again.tess");
    ASSERT_TRUE(imported);
    const ImageInfo& a = (*archive)->images()[0];
    const ImageInfo& b = (*imported)->images()[0];
    ASSERT_EQ(a.level_count, b.level_count);
    for (uint32_t l = 0; l < a.level_count; ++l) {
      const PixelRect whole{0, 0, a.levelWidthPx(l), a.levelHeightPx(l)};
      auto pa = (*archive)->readRegion(0, l, whole);
      auto pb = (*imported)->readRegion(0, l, whole);
      ASSERT_TRUE(pa && pb);
      int worst = 0;
      uint64_t sum = 0;
      for (size_t i = 0; i < pa->texels.size(); ++i) {
        const int delta = std::abs(int(pa->texels[i]) - int(pb->texels[i]));
        worst = std::max(worst, delta);
        sum += delta;
      }
      // Copied levels are the same payloads: exact (all of level 0; the TIFF pads edge tiles
      // as the archive does, so every level but the coarsest). The coarsest is computed again
      // from a decoded level; Deep Zoom's cropped edge tiles are encoded again, so its coarser
      // levels carry two generations of JPEG error.
      const bool copied = l == 0 || (format == ExportFormat::kTiff && l + 1 < a.level_count);
      if (copied) {
        EXPECT_EQ(worst, 0) << exported << " level " << l;
      } else {
        const double limit =
            format == ExportFormat::kTiff ? kComputedMeanLimit : 2 * kComputedMeanLimit;
        EXPECT_LE(double(sum) / pa->texels.size(), limit) << exported << " level " << l;
      }
    }
    fs::remove(dir_ + "again.tess");
  }
}

}  // namespace
}  // namespace tessera::detail
