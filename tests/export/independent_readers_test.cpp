// Exports read back by the tools people will open them with: GDAL (`gdalinfo -json`) for the
// pyramidal GeoTIFF and MBTiles, libvips (`vips copy`, `vips rawsave`) for the TIFF's levels,
// 8-bit and wide. Each test skips, saying so, where the tool is not installed
// (scripts/install-deps.sh installs both).
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>

#include <gtest/gtest.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/build.h>
#include <tessera/open.h>

#include "export/export.h"
#include "support/archive_fixture.h"
#include "support/test_images.h"
#include "support/wide_archive.h"

namespace tessera::detail {
namespace {

namespace fs = std::filesystem;

bool onPath(const std::string& tool) {
  return std::system(("command -v " + tool + " >/dev/null 2>&1").c_str()) == 0;
}

// Runs a shell command (arguments are test paths without quotes or spaces) and returns its
// standard output; fails the test when it exits non-zero.
std::string run(const std::string& command) {
  std::string out;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) {
    ADD_FAILURE() << "cannot run " << command;
    return out;
  }
  char buffer[4096];
  for (size_t n; (n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0;) out.append(buffer, n);
  const int status = ::pclose(pipe);
  EXPECT_EQ(status, 0) << command << ":\n" << out;
  return out;
}

class IndependentReaders : public ::testing::Test {
 protected:
  // A 1000 x 700 GeoTIFF (UTM 33N, 10 m pixels) built into a JPEG archive and exported.
  void SetUp() override {
    dir_ = test::testTempDir() + "/export-readers-" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name() + "/";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    test::TiffSpec spec{.width_px = 1000, .height_px = 700, .samples = 3};
    spec.geo.model_pixel_scale = {10.0, 10.0, 0.0};
    spec.geo.model_tiepoint = {0, 0, 0, 500000.0, 6000000.0, 0};
    spec.geo.geo_key_directory = {1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32633};
    ASSERT_EQ(test::writeTiff(dir_ + "utm.tif", spec, test::makeTestPixels(1000, 700, 3, 9)), "");
    BuildOptions build;
    build.inputs = {dir_ + "utm.tif"};
    build.output = dir_ + "utm.tess";
    Result<BuildReport> built = buildArchive(build);
    ASSERT_TRUE(built) << built.error().message;
    Result<std::shared_ptr<Archive>> opened = openArchive(build.output);
    ASSERT_TRUE(opened) << opened.error().message;
    archive_ = *opened;
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string exportTo(ExportFormat format, const std::string& name) {
    ExportOptions options;
    options.format = format;
    Result<ExportReport> report = exportArchive(*archive_, dir_ + name, options);
    EXPECT_TRUE(report) << report.error().message;
    return dir_ + name;
  }

  std::string dir_;
  std::shared_ptr<Archive> archive_;
};

TEST_F(IndependentReaders, GdalPlacesTheTiffWhereTheSourceWasAndSeesItsLevels) {
  if (!onPath("gdalinfo")) GTEST_SKIP() << "gdalinfo not installed (Debian: gdal-bin)";
  const std::string tif = exportTo(ExportFormat::kTiff, "utm-out.tif");
  const nlohmann::json info = nlohmann::json::parse(run("gdalinfo -json " + tif));
  EXPECT_EQ(info["size"], nlohmann::json({1000, 700}));
  EXPECT_EQ(info["geoTransform"], nlohmann::json({500000.0, 10.0, 0.0, 6000000.0, 0.0, -10.0}));
  EXPECT_NE(info["coordinateSystem"]["wkt"].get<std::string>().find("ID[\"EPSG\",32633]"),
            std::string::npos);
  const ImageInfo& image = archive_->images()[0];
  ASSERT_EQ(info["bands"].size(), 3u);
  const nlohmann::json& overviews = info["bands"][0]["overviews"];
  ASSERT_EQ(overviews.size(), image.level_count - 1);
  for (uint32_t level = 1; level < image.level_count; ++level)
    EXPECT_EQ(overviews[level - 1]["size"],
              nlohmann::json({image.levelWidthPx(level), image.levelHeightPx(level)}));
}

TEST_F(IndependentReaders, GdalOpensTheMbtilesAsAWebMercatorRaster) {
  if (!onPath("gdalinfo")) GTEST_SKIP() << "gdalinfo not installed (Debian: gdal-bin)";
  const std::string mbtiles = exportTo(ExportFormat::kMbtiles, "utm.mbtiles");
  const nlohmann::json info = nlohmann::json::parse(run("gdalinfo -json " + mbtiles));
  EXPECT_EQ(info["driverShortName"], "MBTiles");
  EXPECT_NE(info["coordinateSystem"]["wkt"].get<std::string>().find("3857"), std::string::npos);
  // The image is 1000 px wide: its deepest zoom is 2 (1024 px), and GDAL sees the world square.
  EXPECT_EQ(info["size"][0], info["size"][1]);
  EXPECT_GE(info["size"][0].get<int>(), 1000);
}

TEST_F(IndependentReaders, VipsReadsEveryTiffLevelAsTheArchiveHoldsIt) {
  if (!onPath("vips")) GTEST_SKIP() << "vips not installed (Debian: libvips-tools)";
  const std::string tif = exportTo(ExportFormat::kTiff, "utm-out.tif");
  const ImageInfo& image = archive_->images()[0];
  for (uint32_t level = 0; level < image.level_count; ++level) {
    const std::string png = fmt::format("{}level{}.png", dir_, level);
    run(fmt::format("vips copy '{}[page={}]' {}", tif, level, png));
    const Image read = test::readSource(png);
    Result<Image> expected = archive_->readRegion(
        0, level, {0, 0, image.levelWidthPx(level), image.levelHeightPx(level)});
    ASSERT_TRUE(expected) << expected.error().message;
    ASSERT_EQ(read.width_px, expected->width_px) << "level " << level;
    ASSERT_EQ(read.height_px, expected->height_px) << "level " << level;
    ASSERT_EQ(read.channels, expected->channels) << "level " << level;
    int worst = 0;
    for (size_t i = 0; i < read.texels.size(); ++i)
      worst = std::max(worst, std::abs(int(read.texels[i]) - int(expected->texels[i])));
    // The same JPEG payloads through libvips' libjpeg path and Tessera's TurboJPEG one.
    EXPECT_LE(worst, 2) << "level " << level;
  }
}

// u16 gray and f32 RGB (with NaN, infinities and -0) exported to TIFF: GDAL sees the sample type
// and every level as an overview; vips writes each level's samples raw (its own libtiff
// reading, no conversion), and they are the archive's bit for bit.
TEST(IndependentWideReaders, GdalAndVipsTakeTheWideTiffsSamplesAsTheArchiveHoldsThem) {
  const bool gdal = onPath("gdalinfo"), vips = onPath("vips");
  if (!gdal && !vips) GTEST_SKIP() << "neither gdalinfo nor vips installed";
  const std::string dir = test::testTempDir() + "/export-readers-wide/";
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (const auto& [type, channels] : {std::pair{SampleType::kU16, 1u}, {SampleType::kF32, 3u}}) {
    SCOPED_TRACE(sampleTypeName(type));
    std::shared_ptr<Archive> archive = test::buildWideArchive(
        dir + "wide.tess", 150, 100, channels, type, [&](uint32_t x, uint32_t y, uint32_t c) {
          if (type == SampleType::kU16) return double((x * 389 + y * 1201 + c) % 65536);
          switch ((x + 3 * y + c) % 9) {
            case 0: return std::numeric_limits<double>::quiet_NaN();
            case 1: return -std::numeric_limits<double>::infinity();
            case 2: return -0.0;
            default: return x * 0.25 - y * 3.5;
          }
        });
    ASSERT_TRUE(archive);
    ExportOptions options;
    options.format = ExportFormat::kTiff;
    const std::string tif = dir + "wide.tif";
    Result<ExportReport> report = exportArchive(*archive, tif, options);
    ASSERT_TRUE(report) << report.error().message;
    const ImageInfo& image = archive->images()[0];
    if (gdal) {
      const nlohmann::json info = nlohmann::json::parse(run("gdalinfo -json " + tif));
      ASSERT_EQ(info["bands"].size(), channels);
      EXPECT_EQ(info["bands"][0]["type"], type == SampleType::kU16 ? "UInt16" : "Float32");
      EXPECT_EQ(info["bands"][0]["overviews"].size(), image.level_count - 1);
    }
    for (uint32_t level = 0; vips && level < image.level_count; ++level) {
      const std::string raw = fmt::format("{}level{}.raw", dir, level);
      run(fmt::format("vips rawsave '{}[page={}]' {}", tif, level, raw));
      std::ifstream file(raw, std::ios::binary);
      const std::vector<uint8_t> read{std::istreambuf_iterator<char>(file), {}};
      Result<Image> expected = archive->readRegion(
          0, level, {0, 0, image.levelWidthPx(level), image.levelHeightPx(level)});
      ASSERT_TRUE(expected) << expected.error().message;
      EXPECT_TRUE(read == expected->texels)
          << "level " << level << ": vips gave " << read.size() << " bytes, the archive holds "
          << expected->texels.size();
    }
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera::detail
