// `tessera export` beyond the tiles: the Deep Zoom zip container read back entry by entry
// through minizip's reader, and a GeoTIFF source's georeference written back into the TIFF
// export (read back through libtiff), with malformed georeference entries left out by name.
#include <tiffio.h>
#include <unzip.h>

#include <filesystem>
#include <map>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/build.h>
#include <tessera/open.h>

#include "builder/geotiff_tags.h"
#include "export/export.h"
#include "export_writers.h"
#include "serve/image_metadata.h"
#include "serve/pictures.h"
#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

namespace fs = std::filesystem;

class ExportContainerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::testTempDir() + "/export-container-" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name() + "/";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::shared_ptr<Archive> open(const std::string& path) {
    Result<std::shared_ptr<Archive>> opened = openArchive(path);
    EXPECT_TRUE(opened) << opened.error().message;
    return opened ? *opened : nullptr;
  }

  std::string dir_;
};

struct ZipEntry {
  std::string bytes;
  uLong method = 0;
};

// Every entry of a zip file, by name, through minizip's reader.
std::map<std::string, ZipEntry> readZip(const std::string& path) {
  std::map<std::string, ZipEntry> entries;
  unzFile zip = unzOpen64(path.c_str());
  EXPECT_NE(zip, nullptr) << path;
  if (!zip) return entries;
  for (int at = unzGoToFirstFile(zip); at == UNZ_OK; at = unzGoToNextFile(zip)) {
    unz_file_info64 info{};
    char name[512];
    EXPECT_EQ(unzGetCurrentFileInfo64(zip, &info, name, sizeof name, nullptr, 0, nullptr, 0),
              UNZ_OK);
    ZipEntry entry;
    entry.method = info.compression_method;
    entry.bytes.resize(size_t(info.uncompressed_size));
    EXPECT_EQ(unzOpenCurrentFile(zip), UNZ_OK);
    EXPECT_EQ(unzReadCurrentFile(zip, entry.bytes.data(), unsigned(entry.bytes.size())),
              int(entry.bytes.size()));
    EXPECT_EQ(unzCloseCurrentFile(zip), UNZ_OK) << name << ": CRC mismatch";
    entries.emplace(name, std::move(entry));
  }
  unzClose(zip);
  return entries;
}

// The zip holds NAME/NAME.dzi and NAME/NAME_files/L/C_R.jpg, each stored and equal to what
// the server sends, as vips dzsave --container zip lays it out.
TEST_F(ExportContainerTest, DeepZoomZipHoldsTheServersTilesInVipsLayout) {
  BuildOptions build;
  build.codec = Codec::kJpeg;
  test::BuiltArchive built =
      test::buildFromImage(test::makePatternImage(600, 500, 3, 7), build, dir_);
  std::shared_ptr<Archive> archive = open(built.path);
  ASSERT_TRUE(archive);
  ExportOptions options;
  Result<ExportReport> report = exportArchive(*archive, dir_ + "pic.zip", options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->bytes, fs::file_size(dir_ + "pic.zip"));
  const std::map<std::string, ZipEntry> entries = readZip(dir_ + "pic.zip");
  ASSERT_EQ(entries.size(), report->tiles + 1);
  const ImageInfo& info = archive->images()[0];
  ASSERT_TRUE(entries.count("pic/pic.dzi"));
  EXPECT_EQ(entries.at("pic/pic.dzi").bytes, dziDescriptor(info));
  for (const auto& [name, entry] : entries) {
    EXPECT_EQ(entry.method, 0u) << name << " is not stored";
    if (name == "pic/pic.dzi") continue;
    uint32_t level = 0, col = 0, row = 0;
    ASSERT_EQ(std::sscanf(name.c_str(), "pic/pic_files/%u/%u_%u.jpg", &level, &col, &row), 3)
        << name;
    Result<Picture> expected =
        renderDziTile(*archive, 0, level, col, row, PictureFormat::kJpeg, 85);
    ASSERT_TRUE(expected) << name << ": " << expected.error().message;
    EXPECT_EQ(entry.bytes, expected->bytes) << name;
  }
  // Neither a folder nor a partial file is left beside it; a second export is refused.
  EXPECT_FALSE(fs::exists(dir_ + "pic_files"));
  Result<ExportReport> again = exportArchive(*archive, dir_ + "pic.zip", options);
  EXPECT_TRUE(again) << "a zip is replaced like any other file output";
  Result<ExportReport> unnamed = exportArchive(*archive, dir_ + "pic.out", options);
  ASSERT_FALSE(unnamed);
  EXPECT_NE(unnamed.error().message.find("NAME.zip"), std::string::npos);
}

template <typename T>
std::vector<T> tiffArray(TIFF* tiff, uint32_t tag) {
  uint32_t count = 0;
  T* values = nullptr;
  if (TIFFGetField(tiff, tag, &count, &values) != 1 || !values) return {};
  return std::vector<T>(values, values + count);
}

std::string tiffText(TIFF* tiff, uint32_t tag) {
  const char* text = nullptr;
  if (TIFFGetField(tiff, tag, &text) != 1 || !text) return {};
  return text;
}

// The GeoTIFF tags of `geo` on the first directory of `path`, read through libtiff, and none on
// the first overview.
void expectGeoTagsOnTheFirstDirectoryOnly(const std::string& path, const test::GeoTags& geo) {
  registerGeoTiffTags();
  TIFF* tiff = TIFFOpen(path.c_str(), "r");
  ASSERT_NE(tiff, nullptr);
  EXPECT_EQ(tiffArray<double>(tiff, kTagModelPixelScale), geo.model_pixel_scale);
  EXPECT_EQ(tiffArray<double>(tiff, kTagModelTiepoint), geo.model_tiepoint);
  EXPECT_EQ(tiffArray<uint16_t>(tiff, kTagGeoKeyDirectory), geo.geo_key_directory);
  EXPECT_EQ(tiffArray<double>(tiff, kTagGeoDoubleParams), geo.geo_double_params);
  EXPECT_EQ(tiffText(tiff, kTagGeoAsciiParams), geo.geo_ascii_params);
  EXPECT_EQ(tiffText(tiff, kTagGdalNodata), geo.gdal_nodata);
  EXPECT_TRUE(tiffArray<double>(tiff, kTagModelTransformation).empty());
  ASSERT_EQ(TIFFReadDirectory(tiff), 1);  // the first overview
  EXPECT_TRUE(tiffArray<double>(tiff, kTagModelTiepoint).empty());
  TIFFClose(tiff);
}

// A GeoTIFF's tags go into the archive's metadata at build, then back on the exported
// TIFF's first directory (and on no overview).
TEST_F(ExportContainerTest, TiffExportWritesTheSourcesGeoreferenceBack) {
  test::TiffSpec spec{.width_px = 700, .height_px = 300, .samples = 3};
  spec.geo.model_pixel_scale = {10.0, 10.0, 0.0};
  spec.geo.model_tiepoint = {0, 0, 0, 500000.0, 6000000.0, 0};
  spec.geo.geo_key_directory = {1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32633};
  spec.geo.geo_double_params = {6378137.0, 298.257223563};
  spec.geo.geo_ascii_params = "WGS 84 / UTM zone 33N|";
  spec.geo.gdal_nodata = "0";
  const std::string source = dir_ + "geo.tif";
  ASSERT_EQ(test::writeTiff(source, spec, test::makeTestPixels(700, 300, 3, 5)), "");
  BuildOptions build;
  build.inputs = {source};
  build.output = dir_ + "geo.tess";
  Result<BuildReport> built = buildArchive(build);
  ASSERT_TRUE(built) << built.error().message;
  std::shared_ptr<Archive> archive = open(build.output);
  ASSERT_TRUE(archive);
  ASSERT_FALSE(imageGeoreferenceJson(*archive, 0).empty());

  ExportOptions options;
  options.format = ExportFormat::kTiff;
  Result<ExportReport> report = exportArchive(*archive, dir_ + "out.tif", options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_TRUE(report->georeferenced);
  EXPECT_TRUE(report->warnings.empty());

  expectGeoTagsOnTheFirstDirectoryOnly(dir_ + "out.tif", spec.geo);

  // An archive built from a PNG has no georeference and exports none.
  BuildOptions plain;
  test::BuiltArchive png = test::buildFromImage(test::makePatternImage(64, 64, 3, 1), plain, dir_);
  std::shared_ptr<Archive> plain_archive = open(png.path);
  ASSERT_TRUE(plain_archive);
  EXPECT_TRUE(imageGeoreferenceJson(*plain_archive, 0).empty());
  Result<ExportReport> plain_report = exportArchive(*plain_archive, dir_ + "plain.tif", options);
  ASSERT_TRUE(plain_report) << plain_report.error().message;
  EXPECT_FALSE(plain_report->georeferenced);
}

// A float elevation model keeps its georeference and NoData through the wide (ZSTD) path too.
TEST_F(ExportContainerTest, FloatTiffExportWritesTheSourcesGeoreferenceBack) {
  test::TiffSpec spec{.width_px = 300, .height_px = 200, .samples = 1, .bits = 32};
  spec.sample_format = SAMPLEFORMAT_IEEEFP;
  spec.photometric = PHOTOMETRIC_MINISBLACK;
  spec.geo.model_pixel_scale = {30.0, 30.0, 0.0};
  spec.geo.model_tiepoint = {0, 0, 0, 300000.0, 5000000.0, 0};
  spec.geo.geo_key_directory = {1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32632};
  spec.geo.geo_double_params = {6378137.0, 298.257223563};
  spec.geo.geo_ascii_params = "WGS 84 / UTM zone 32N|";
  spec.geo.gdal_nodata = "-9999";
  const std::string source = dir_ + "dem.tif";
  ASSERT_EQ(test::writeTiff(source, spec, test::makeTestPixels(300, 200, 1, 2)), "");
  BuildOptions build;
  build.inputs = {source};
  build.output = dir_ + "dem.tess";
  build.codec = Codec::kZstd;
  build.tile_size_px = 128;
  Result<BuildReport> built = buildArchive(build);
  ASSERT_TRUE(built) << built.error().message;
  std::shared_ptr<Archive> archive = open(build.output);
  ASSERT_TRUE(archive);
  ASSERT_EQ(archive->images()[0].sample_type, SampleType::kF32);

  ExportOptions options;
  options.format = ExportFormat::kTiff;
  Result<ExportReport> report = exportArchive(*archive, dir_ + "dem-out.tif", options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tile_format, "zstd");
  EXPECT_TRUE(report->georeferenced);
  EXPECT_TRUE(report->warnings.empty());
  expectGeoTagsOnTheFirstDirectoryOnly(dir_ + "dem-out.tif", spec.geo);
}

// Entries that do not hold what their tag does are left out, each named in a warning; the
// good ones are still written.
TEST_F(ExportContainerTest, MalformedGeoreferenceEntriesAreLeftOutByName) {
  registerGeoTiffTags();
  const std::string path = dir_ + "bad-geo.tif";
  TIFF* tiff = TIFFOpen(path.c_str(), "w");
  ASSERT_NE(tiff, nullptr);
  TIFFSetField(tiff, TIFFTAG_IMAGEWIDTH, 1);
  TIFFSetField(tiff, TIFFTAG_IMAGELENGTH, 1);
  TIFFSetField(tiff, TIFFTAG_BITSPERSAMPLE, 8);
  TIFFSetField(tiff, TIFFTAG_SAMPLESPERPIXEL, 1);
  TIFFSetField(tiff, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
  ExportReport report;
  setGeoreferenceTags(tiff,
                      R"({"model_pixel_scale": ["ten", 10, 0], "geo_key_directory": [70000],
                          "model_transformation": [], "gdal_nodata": 0,
                          "model_tiepoint": [0, 0, 0, 1.5, 2.5, 0], "epsg": 4326})",
                      report);
  uint8_t pixel = 7;
  ASSERT_EQ(TIFFWriteScanline(tiff, &pixel, 0, 0), 1);
  TIFFClose(tiff);
  EXPECT_TRUE(report.georeferenced);
  ASSERT_EQ(report.warnings.size(), 4u);
  for (const char* key :
       {"model_pixel_scale", "geo_key_directory", "model_transformation", "gdal_nodata"}) {
    bool named = false;
    for (const std::string& warning : report.warnings)
      named = named || warning.find(std::string("georeference.") + key) != std::string::npos;
    EXPECT_TRUE(named) << key;
  }
  tiff = TIFFOpen(path.c_str(), "r");
  ASSERT_NE(tiff, nullptr);
  EXPECT_EQ(tiffArray<double>(tiff, kTagModelTiepoint),
            (std::vector<double>{0, 0, 0, 1.5, 2.5, 0}));
  EXPECT_TRUE(tiffArray<double>(tiff, kTagModelPixelScale).empty());
  EXPECT_TRUE(tiffArray<uint16_t>(tiff, kTagGeoKeyDirectory).empty());
  TIFFClose(tiff);

  ExportReport not_object;
  setGeoreferenceTags(nullptr, "[1, 2]", not_object);
  EXPECT_FALSE(not_object.georeferenced);
  EXPECT_EQ(not_object.warnings.size(), 1u);
}

}  // namespace
}  // namespace tessera::detail
