// `tessera export`'s library: PMTiles ids and directories against hand-computed bytes and the
// Hilbert curve's defining property; MBTiles and Deep Zoom outputs read back tile for tile
// against the server's own tile cutting; outputs refused, kept, or never half-written.
#include "export/export.h"

#include <sqlite3.h>
#include <tiffio.h>
#include <sys/stat.h>

#include <filesystem>
#include <set>

#include <gtest/gtest.h>

#include <tessera/open.h>

#include "export/pmtiles.h"
#include "export_writers.h"
#include "serve/pictures.h"
#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

namespace fs = std::filesystem;

TEST(Pmtiles, TileIdsFollowTheHilbertCurveZoomAfterZoom) {
  EXPECT_EQ(pmtiles::tileId(0, 0, 0), 0u);
  EXPECT_EQ(pmtiles::tileId(1, 0, 0), 1u);
  EXPECT_EQ(pmtiles::tileId(1, 0, 1), 2u);
  EXPECT_EQ(pmtiles::tileId(1, 1, 1), 3u);
  EXPECT_EQ(pmtiles::tileId(1, 1, 0), 4u);
  uint64_t base = 0;
  for (uint32_t z = 0; z <= 6; ++z) {
    const uint32_t n = 1u << z;
    std::vector<std::pair<uint32_t, uint32_t>> at(size_t(n) * n, {n, n});
    for (uint32_t y = 0; y < n; ++y) {
      for (uint32_t x = 0; x < n; ++x) {
        const uint64_t id = pmtiles::tileId(z, x, y);
        ASSERT_GE(id, base);
        ASSERT_LT(id, base + uint64_t(n) * n);
        ASSERT_EQ(at[id - base].first, n) << "id " << id << " given twice";
        at[id - base] = {x, y};
      }
    }
    // A Hilbert curve moves to a 4-neighbour at every step.
    for (size_t i = 1; i < at.size(); ++i) {
      const int dx = int(at[i].first) - int(at[i - 1].first);
      const int dy = int(at[i].second) - int(at[i - 1].second);
      ASSERT_EQ(std::abs(dx) + std::abs(dy), 1) << "zoom " << z << " step " << i;
    }
    base += uint64_t(n) * n;
  }
}

TEST(Pmtiles, DirectoryColumnsByHand) {
  const std::vector<pmtiles::Entry> entries = {{5, 0, 100, 1}, {6, 100, 50, 2}, {10, 400, 7, 1}};
  const std::vector<uint8_t> expected = {3,             // entries
                                         5,    1,   4,  // id deltas
                                         1,    2,   1,  // run lengths
                                         100,  50,  7,  // lengths
                                         1,    0,       // offset 0 (+1), then follows the previous
                                         0x91, 0x03};   // 400 + 1 as a varint
  EXPECT_EQ(pmtiles::encodeDirectory(entries), expected);
}

TEST(Pmtiles, HeaderFieldsWhereTheSpecPutsThem) {
  pmtiles::Header header;
  header.root_offset = 127;
  header.root_bytes = 0x1234;
  header.tile_data_offset = 16384;
  header.addressed_tiles = 85;
  header.tile_type = pmtiles::TileType::kJpeg;
  header.max_zoom = 3;
  const std::vector<uint8_t> bytes = pmtiles::encodeHeader(header);
  ASSERT_EQ(bytes.size(), 127u);
  EXPECT_EQ(std::string(bytes.begin(), bytes.begin() + 7), "PMTiles");
  EXPECT_EQ(bytes[7], 3);
  EXPECT_EQ(bytes[8], 127);
  EXPECT_EQ(bytes[16], 0x34);
  EXPECT_EQ(bytes[17], 0x12);
  EXPECT_EQ(bytes[56 + 1], 0x40);  // 16384
  EXPECT_EQ(bytes[72], 85);
  EXPECT_EQ(bytes[96], 1);  // clustered
  EXPECT_EQ(bytes[97], 1);  // directories not compressed
  EXPECT_EQ(bytes[98], 1);  // tiles stored as image files
  EXPECT_EQ(bytes[99], 3);
  EXPECT_EQ(bytes[101], 3);
}

class ExportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::testTempDir() + "/export-" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name() + "/";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    BuildOptions options;
    options.codec = Codec::kJpeg;
    built_ = test::buildFromImage(test::makePatternImage(600, 500, 3, 7), options, dir_);
    ASSERT_FALSE(built_.bytes.empty());
    Result<std::shared_ptr<Archive>> opened = openArchive(built_.path);
    ASSERT_TRUE(opened) << opened.error().message;
    archive_ = *opened;
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::vector<std::string> partials() const {
    std::vector<std::string> found;
    for (const auto& entry : fs::directory_iterator(dir_))
      if (entry.path().filename().string().find(".partial-") != std::string::npos)
        found.push_back(entry.path().string());
    return found;
  }

  std::string dir_;
  test::BuiltArchive built_;
  std::shared_ptr<Archive> archive_;
};

TEST_F(ExportTest, MbtilesHoldsEveryXyzTileWithItsRowCountedFromTheBottom) {
  ExportOptions options;
  options.format = ExportFormat::kMbtiles;
  const std::string out = dir_ + "out.mbtiles";
  Result<ExportReport> report = exportArchive(*archive_, out, options);
  ASSERT_TRUE(report) << report.error().message;
  const ImageInfo& info = archive_->images()[0];
  EXPECT_EQ(report->tiles, xyzTilesOf(info).size());
  EXPECT_GT(report->tiles_copied, 0u);  // 256-px JPEG tiles inside the image go as stored
  EXPECT_EQ(report->tile_format, "jpg");

  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(out.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* query = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT zoom_level, tile_column, tile_row, tile_data FROM tiles",
                               -1, &query, nullptr),
            SQLITE_OK);
  size_t rows = 0;
  while (sqlite3_step(query) == SQLITE_ROW) {
    const uint32_t z = uint32_t(sqlite3_column_int(query, 0));
    const uint32_t x = uint32_t(sqlite3_column_int(query, 1));
    const uint32_t y = (1u << z) - 1 - uint32_t(sqlite3_column_int(query, 2));
    const std::string stored(static_cast<const char*>(sqlite3_column_blob(query, 3)),
                             size_t(sqlite3_column_bytes(query, 3)));
    Result<Picture> expected = renderXyzTile(*archive_, 0, z, x, y, PictureFormat::kJpeg, 85);
    ASSERT_TRUE(expected) << z << "/" << x << "/" << y << ": " << expected.error().message;
    EXPECT_EQ(stored, expected->bytes) << z << "/" << x << "/" << y;
    ++rows;
  }
  sqlite3_finalize(query);
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT value FROM metadata WHERE name = 'format'", -1, &query,
                               nullptr),
            SQLITE_OK);
  ASSERT_EQ(sqlite3_step(query), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(query, 0)), "jpg");
  sqlite3_finalize(query);
  sqlite3_close(db);
  EXPECT_EQ(rows, report->tiles);
  EXPECT_TRUE(partials().empty());
}

TEST_F(ExportTest, DeepZoomFolderHoldsWhatTheServerSends) {
  ExportOptions options;
  const std::string out = dir_ + "pic.dzi";
  Result<ExportReport> report = exportArchive(*archive_, out, options);
  ASSERT_TRUE(report) << report.error().message;
  const ImageInfo& info = archive_->images()[0];
  const std::string descriptor = dziDescriptor(info);
  EXPECT_EQ(test::readFileBytes(out), std::vector<uint8_t>(descriptor.begin(), descriptor.end()));
  uint64_t files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(dir_ + "pic_files")) {
    if (!entry.is_regular_file()) continue;
    const uint32_t level = uint32_t(std::stoul(entry.path().parent_path().filename().string()));
    uint32_t col = 0, row = 0;
    ASSERT_EQ(std::sscanf(entry.path().filename().c_str(), "%u_%u.jpg", &col, &row), 2);
    Result<Picture> expected =
        renderDziTile(*archive_, 0, level, col, row, PictureFormat::kJpeg, 85);
    ASSERT_TRUE(expected) << entry.path() << ": " << expected.error().message;
    const std::vector<uint8_t> bytes = test::readFileBytes(entry.path().string());
    EXPECT_EQ(std::string(bytes.begin(), bytes.end()), expected->bytes) << entry.path();
    ++files;
  }
  EXPECT_EQ(files, report->tiles);
  EXPECT_EQ(dziMaxLevel(info) + 1,
            uint32_t(std::distance(fs::directory_iterator(dir_ + "pic_files"),
                                   fs::directory_iterator())));

  // A second export to the same name is refused and leaves the first one as it was.
  const auto before = fs::last_write_time(dir_ + "pic_files/0/0_0.jpg");
  Result<ExportReport> again = exportArchive(*archive_, out, options);
  ASSERT_FALSE(again);
  EXPECT_NE(again.error().message.find("pic_files: exists"), std::string::npos);
  EXPECT_EQ(fs::last_write_time(dir_ + "pic_files/0/0_0.jpg"), before);
  EXPECT_TRUE(partials().empty());
}

TEST_F(ExportTest, SpecialFilesAtTheOutputAreRefusedAndKept) {
  const std::string fifo = dir_ + "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (ExportFormat format :
       {ExportFormat::kPmtiles, ExportFormat::kMbtiles, ExportFormat::kTiff}) {
    ExportOptions options;
    options.format = format;
    Result<ExportReport> report = exportArchive(*archive_, fifo, options);
    ASSERT_FALSE(report);
    EXPECT_NE(report.error().message.find("FIFO"), std::string::npos) << report.error().message;
    EXPECT_TRUE(fs::is_fifo(fifo));
  }
  ExportOptions options;
  Result<ExportReport> not_dzi = exportArchive(*archive_, dir_ + "picture", options);
  ASSERT_FALSE(not_dzi);
  EXPECT_NE(not_dzi.error().message.find("NAME.dzi"), std::string::npos);
  options.image = 3;
  Result<ExportReport> no_image = exportArchive(*archive_, dir_ + "x.dzi", options);
  ASSERT_FALSE(no_image);
  EXPECT_NE(no_image.error().message.find("no image 3"), std::string::npos);
  EXPECT_TRUE(partials().empty());
}

// Reads every directory of a pyramidal TIFF back through libtiff (JPEG tiles decoded to RGB by
// libtiff's own JPEG path) and compares each level with the archive's, within `tolerance`.
void expectTiffMatchesArchive(const std::string& path, const Archive& archive, int tolerance) {
  const ImageInfo& info = archive.images()[0];
  TIFF* tiff = TIFFOpen(path.c_str(), "r");
  ASSERT_NE(tiff, nullptr) << path;
  uint32_t level = 0;
  do {
    ASSERT_LT(level, info.level_count);
    uint32_t width = 0, height = 0, tile_w = 0, subfile = 0;
    uint16_t compression = 0, samples = 0;
    TIFFGetField(tiff, TIFFTAG_IMAGEWIDTH, &width);
    TIFFGetField(tiff, TIFFTAG_IMAGELENGTH, &height);
    TIFFGetField(tiff, TIFFTAG_TILEWIDTH, &tile_w);
    TIFFGetFieldDefaulted(tiff, TIFFTAG_SUBFILETYPE, &subfile);
    TIFFGetField(tiff, TIFFTAG_COMPRESSION, &compression);
    TIFFGetField(tiff, TIFFTAG_SAMPLESPERPIXEL, &samples);
    EXPECT_EQ(width, info.levelWidthPx(level));
    EXPECT_EQ(height, info.levelHeightPx(level));
    EXPECT_EQ(tile_w, info.tile_size_px);
    EXPECT_EQ(subfile, level == 0 ? 0u : uint32_t(FILETYPE_REDUCEDIMAGE));
    EXPECT_EQ(samples, info.channels);
    if (compression == COMPRESSION_JPEG)
      TIFFSetField(tiff, TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
    Result<Image> expected = archive.readRegion(0, level, {0, 0, width, height});
    ASSERT_TRUE(expected) << expected.error().message;
    std::vector<uint8_t> tile(size_t(TIFFTileSize(tiff)));
    int worst = 0;
    for (uint32_t ty = 0; ty < height; ty += tile_w) {
      for (uint32_t tx = 0; tx < width; tx += tile_w) {
        ASSERT_GT(TIFFReadTile(tiff, tile.data(), tx, ty, 0, 0), 0)
            << level << " " << tx << "," << ty;
        for (uint32_t y = ty; y < std::min(height, ty + tile_w); ++y)
          for (uint32_t x = tx; x < std::min(width, tx + tile_w); ++x)
            for (uint32_t c = 0; c < info.channels; ++c)
              worst = std::max(
                  worst,
                  std::abs(int(tile[(size_t(y - ty) * tile_w + (x - tx)) * info.channels + c]) -
                           int(expected->row(y)[size_t(x) * info.channels + c])));
      }
    }
    EXPECT_LE(worst, tolerance) << "level " << level;
    ++level;
  } while (TIFFReadDirectory(tiff));
  EXPECT_EQ(level, info.level_count);
  TIFFClose(tiff);
}

TEST_F(ExportTest, TiffPyramidCopiesJpegTilesAndReadsBackThroughLibtiff) {
  ExportOptions options;
  options.format = ExportFormat::kTiff;
  const std::string out = dir_ + "pyramid.tif";
  Result<ExportReport> report = exportArchive(*archive_, out, options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tile_format, "jpeg");
  EXPECT_GT(report->tiles_copied, 0u);
  // libtiff's JPEG path upsamples chroma its own way: within 2 of the archive's decoder.
  expectTiffMatchesArchive(out, *archive_, 2);
  EXPECT_TRUE(partials().empty());
}

TEST_F(ExportTest, TiffOfALosslessArchiveWithAlphaAndBorderIsExact) {
  BuildOptions build;
  build.codec = Codec::kWebp;
  build.border_px = 2;
  test::BuiltArchive rgba =
      test::buildFromImage(test::makePatternImage(700, 300, 4, 3), build, dir_, "rgba.tess");
  Result<std::shared_ptr<Archive>> opened = openArchive(rgba.path);
  ASSERT_TRUE(opened) << opened.error().message;
  ExportOptions options;
  options.format = ExportFormat::kTiff;
  Result<ExportReport> report = exportArchive(**opened, dir_ + "rgba.tif", options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tile_format, "deflate");
  EXPECT_EQ(report->tiles_copied, 0u);
  expectTiffMatchesArchive(dir_ + "rgba.tif", **opened, 0);
}

// A payload that fails its checksum ends the export with the tile named; nothing is left at
// the output, not even a partial file or folder.
TEST_F(ExportTest, ACorruptTileFailsTheExportAndLeavesNothing) {
  std::vector<uint8_t> bytes = built_.bytes;
  Result<TileEntry> entry = archive_->tileEntry({0, 0, 0, 0});
  ASSERT_TRUE(entry);
  ASSERT_EQ(entry->kind, TileKind::kEncoded);
  test::flipBit(bytes, size_t(entry->offset_bytes + entry->length_bytes / 2), 3);
  const std::string corrupt = dir_ + "corrupt.tess";
  ASSERT_TRUE(test::writeFileBytes(corrupt, bytes));
  Result<std::shared_ptr<Archive>> opened = openArchive(corrupt);
  ASSERT_TRUE(opened);
  for (ExportFormat format : {ExportFormat::kDeepZoom, ExportFormat::kPmtiles,
                              ExportFormat::kMbtiles, ExportFormat::kTiff}) {
    ExportOptions options;
    options.format = format;
    const std::string out = dir_ + (format == ExportFormat::kDeepZoom ? "c.dzi" : "c.out");
    Result<ExportReport> report = exportArchive(**opened, out, options);
    ASSERT_FALSE(report);
    EXPECT_NE(report.error().message.find("checksum"), std::string::npos) << report.error().message;
    EXPECT_FALSE(fs::exists(out));
    EXPECT_FALSE(fs::exists(dir_ + "c_files"));
    EXPECT_TRUE(partials().empty());
  }
  Result<ExportReport> zip = exportArchive(**opened, dir_ + "c.zip", ExportOptions{});
  ASSERT_FALSE(zip);
  EXPECT_FALSE(fs::exists(dir_ + "c.zip"));
  EXPECT_TRUE(partials().empty());
}

}  // namespace
}  // namespace tessera::detail
