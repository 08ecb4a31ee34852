#include <cstdlib>
#include <cstring>
#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <tiffio.h>

#include "builder/band_reader.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using test::TiffSpec;
using ::testing::HasSubstr;

// Writes `spec` with test pixels to a fresh file; returns its path.
std::string writeFixture(const TiffSpec& spec, const std::string& name,
                         std::vector<uint8_t>* pixels_out = nullptr) {
  const std::string path = test::testTempDir() + name;
  std::vector<uint8_t> pixels = test::makeTestPixels(spec.width_px, spec.height_px, spec.samples);
  const std::string error = test::writeTiff(path, spec, pixels);
  EXPECT_EQ(error, "");
  if (pixels_out) *pixels_out = std::move(pixels);
  return path;
}

// Pixels as the reader should return them: extra samples past the first dropped.
std::vector<uint8_t> keepChannels(const std::vector<uint8_t>& pixels, uint32_t samples,
                                  uint32_t channels) {
  std::vector<uint8_t> out;
  for (size_t i = 0; i < pixels.size(); i += samples) {
    out.insert(out.end(), pixels.begin() + i, pixels.begin() + i + channels);
  }
  return out;
}

std::vector<uint8_t> readWhole(const std::string& path, uint32_t band_rows, SourceInfo* info) {
  auto reader = openTiffReader(path);
  EXPECT_TRUE(reader.has_value()) << (reader ? "" : reader.error().message);
  if (!reader) return {};
  *info = (*reader)->info();
  std::string error;
  std::vector<uint8_t> out = test::readAllRows(**reader, band_rows, &error);
  EXPECT_EQ(error, "");
  return out;
}

struct LayoutCase {
  const char* name;
  uint16_t samples;
  uint16_t photometric;
  uint16_t compression;
  uint16_t planar;
  bool tiled;
  bool bigtiff;
  uint32_t rows_per_strip;
};

class TiffLayoutTest : public ::testing::TestWithParam<LayoutCase> {};

TEST_P(TiffLayoutTest, RoundTripsExactly) {
  const LayoutCase& c = GetParam();
  TiffSpec spec;
  spec.width_px = 53;  // not a tile multiple: edge tiles are partial
  spec.height_px = 41;
  spec.samples = c.samples;
  spec.photometric = c.photometric;
  spec.compression = c.compression;
  spec.planar = c.planar;
  spec.tiled = c.tiled;
  spec.bigtiff = c.bigtiff;
  spec.rows_per_strip = c.rows_per_strip;
  if (c.compression == COMPRESSION_ADOBE_DEFLATE || c.compression == COMPRESSION_LZW) {
    spec.predictor = PREDICTOR_HORIZONTAL;
  }
  std::vector<uint8_t> pixels;
  const std::string path = writeFixture(spec, std::string(c.name) + ".tif", &pixels);
  const uint32_t colour = c.photometric == PHOTOMETRIC_RGB ? 3 : 1;
  const uint32_t channels = std::min<uint32_t>(c.samples, colour + 1);
  std::vector<uint8_t> expected = keepChannels(pixels, c.samples, channels);
  if (c.photometric == PHOTOMETRIC_MINISWHITE) {
    for (size_t i = 0; i < expected.size(); i += channels) expected[i] = uint8_t(255 - expected[i]);
  }
  for (uint32_t band_rows : {1u, 7u, 16u, 41u}) {
    SourceInfo info;
    const std::vector<uint8_t> got = readWhole(path, band_rows, &info);
    EXPECT_EQ(info.width_px, 53u);
    EXPECT_EQ(info.height_px, 41u);
    EXPECT_EQ(info.channels, channels);
    EXPECT_GE(info.natural_band_rows, 1u);
    EXPECT_EQ(info.format, "tiff");
    EXPECT_EQ(info.metadata["tiff"]["layout"], c.tiled ? "tiled" : "striped");
    EXPECT_EQ(info.metadata["tiff"]["bigtiff"], c.bigtiff);
    ASSERT_EQ(got.size(), expected.size());
    EXPECT_TRUE(got == expected) << c.name << " differs when read in bands of " << band_rows;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Layouts, TiffLayoutTest,
    ::testing::Values(LayoutCase{"StripedRgb", 3, PHOTOMETRIC_RGB, COMPRESSION_NONE,
                                 PLANARCONFIG_CONTIG, false, false, 8},
                      LayoutCase{"StripedGray", 1, PHOTOMETRIC_MINISBLACK, COMPRESSION_NONE,
                                 PLANARCONFIG_CONTIG, false, false, 5},
                      LayoutCase{"StripedMinIsWhite", 1, PHOTOMETRIC_MINISWHITE, COMPRESSION_NONE,
                                 PLANARCONFIG_CONTIG, false, false, 8},
                      LayoutCase{"StripedGrayAlpha", 2, PHOTOMETRIC_MINISBLACK, COMPRESSION_LZW,
                                 PLANARCONFIG_CONTIG, false, false, 8},
                      LayoutCase{"StripedRgbaDeflate", 4, PHOTOMETRIC_RGB,
                                 COMPRESSION_ADOBE_DEFLATE, PLANARCONFIG_CONTIG, false, false, 8},
                      LayoutCase{"StripedRgbPackBits", 3, PHOTOMETRIC_RGB, COMPRESSION_PACKBITS,
                                 PLANARCONFIG_CONTIG, false, false, 3},
                      LayoutCase{"StripedRgbLzwSingleStrip", 3, PHOTOMETRIC_RGB, COMPRESSION_LZW,
                                 PLANARCONFIG_CONTIG, false, false, 41},
                      LayoutCase{"StripedRgbBigTiff", 3, PHOTOMETRIC_RGB, COMPRESSION_NONE,
                                 PLANARCONFIG_CONTIG, false, true, 8},
                      LayoutCase{"TiledRgb", 3, PHOTOMETRIC_RGB, COMPRESSION_NONE,
                                 PLANARCONFIG_CONTIG, true, false, 0},
                      LayoutCase{"TiledGrayDeflate", 1, PHOTOMETRIC_MINISBLACK,
                                 COMPRESSION_ADOBE_DEFLATE, PLANARCONFIG_CONTIG, true, false, 0},
                      LayoutCase{"TiledRgbaBigTiffLzw", 4, PHOTOMETRIC_RGB, COMPRESSION_LZW,
                                 PLANARCONFIG_CONTIG, true, true, 0},
                      LayoutCase{"PlanarStripedRgb", 3, PHOTOMETRIC_RGB, COMPRESSION_NONE,
                                 PLANARCONFIG_SEPARATE, false, false, 8},
                      LayoutCase{"PlanarStripedRgbaDeflate", 4, PHOTOMETRIC_RGB,
                                 COMPRESSION_ADOBE_DEFLATE, PLANARCONFIG_SEPARATE, false, false, 8},
                      LayoutCase{"PlanarStripedGrayAlphaLzw", 2, PHOTOMETRIC_MINISBLACK,
                                 COMPRESSION_LZW, PLANARCONFIG_SEPARATE, false, false, 16},
                      LayoutCase{"PlanarTiledRgbDeflate", 3, PHOTOMETRIC_RGB,
                                 COMPRESSION_ADOBE_DEFLATE, PLANARCONFIG_SEPARATE, true, true, 0},
                      LayoutCase{"PlanarTiledRgbaNone", 4, PHOTOMETRIC_RGB, COMPRESSION_NONE,
                                 PLANARCONFIG_SEPARATE, true, false, 0},
                      LayoutCase{"ExtraSamplesDropped", 5, PHOTOMETRIC_RGB, COMPRESSION_NONE,
                                 PLANARCONFIG_CONTIG, false, false, 8},
                      LayoutCase{"PlanarExtraSamplesDropped", 6, PHOTOMETRIC_RGB, COMPRESSION_LZW,
                                 PLANARCONFIG_SEPARATE, true, false, 0}),
    [](const ::testing::TestParamInfo<LayoutCase>& param) {
      return std::string(param.param.name);
    });

TEST(TiffReader, ReadsTiledBigTiffInBands) {
  TiffSpec spec{.width_px = 100,
                .height_px = 70,
                .samples = 3,
                .bigtiff = true,
                .tiled = true,
                .tile_width_px = 32,
                .tile_height_px = 32};
  std::vector<uint8_t> pixels;
  const std::string path = writeFixture(spec, "tiled.tif", &pixels);
  auto reader = openTiffReader(path);
  ASSERT_TRUE(reader.has_value()) << reader.error().message;
  EXPECT_EQ((*reader)->info().natural_band_rows, 32u);
  EXPECT_EQ((*reader)->info().metadata["tiff"]["tile_width"], 32);
  std::string error;
  EXPECT_TRUE(test::readAllRows(**reader, 32, &error) == pixels);
  EXPECT_EQ(error, "");
}

TEST(TiffReader, ReadsJpegCompressedYcbcrAsRgb) {
  for (bool tiled : {false, true}) {
    TiffSpec spec{.width_px = 64,
                  .height_px = 48,
                  .samples = 3,
                  .compression = COMPRESSION_JPEG,
                  .tiled = tiled,
                  .rows_per_strip = 16};
    std::vector<uint8_t> pixels;
    const std::string path = writeFixture(spec, "jpeg.tif", &pixels);
    SourceInfo info;
    const std::vector<uint8_t> got = readWhole(path, 10, &info);
    ASSERT_EQ(got.size(), pixels.size());
    EXPECT_EQ(info.metadata["tiff"]["compression"], "jpeg");
    EXPECT_EQ(info.metadata["tiff"]["photometric"], "ycbcr");
    double total = 0;
    int worst = 0;
    for (size_t i = 0; i < got.size(); ++i) {
      const int delta = std::abs(int(got[i]) - int(pixels[i]));
      total += delta;
      worst = std::max(worst, delta);
    }
    EXPECT_LT(total / double(got.size()), 4.0) << (tiled ? "tiled" : "striped");
    EXPECT_LT(worst, 48) << (tiled ? "tiled" : "striped");
  }
}

TEST(TiffReader, ReadsTallSingleStripInBoundedBands) {
  for (uint16_t compression : {COMPRESSION_NONE, COMPRESSION_ADOBE_DEFLATE}) {
    TiffSpec spec{.width_px = 20,
                  .height_px = 3000,
                  .samples = 1,
                  .photometric = PHOTOMETRIC_MINISBLACK,
                  .compression = compression,
                  .rows_per_strip = 3000};
    std::vector<uint8_t> pixels;
    const std::string path = writeFixture(spec, "tall.tif", &pixels);
    SourceInfo info;
    const std::vector<uint8_t> got = readWhole(path, 100, &info);
    EXPECT_LE(info.natural_band_rows, 256u);
    EXPECT_TRUE(got == pixels);
  }
}

TEST(TiffReader, ExtractsGeoTiffMetadataAndEpsg) {
  TiffSpec spec{
      .width_px = 16, .height_px = 16, .samples = 1, .photometric = PHOTOMETRIC_MINISBLACK};
  spec.geo.model_pixel_scale = {10.0, 10.0, 0.0};
  spec.geo.model_tiepoint = {0, 0, 0, 500000.0, 6000000.0, 0};
  // Version 1.1.0, 3 keys: model type projected, raster is area, ProjectedCSType 32633.
  spec.geo.geo_key_directory = {1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32633};
  spec.geo.geo_double_params = {6378137.0, 298.257223563};
  spec.geo.geo_ascii_params = "WGS 84 / UTM zone 33N|";
  spec.geo.gdal_nodata = "0";
  spec.geo.gdal_metadata = "<GDALMetadata><Item name=\"AREA\">x</Item></GDALMetadata>";
  const std::string path = writeFixture(spec, "geo.tif");
  auto reader = openTiffReader(path);
  ASSERT_TRUE(reader.has_value()) << reader.error().message;
  const nlohmann::json& geo = (*reader)->info().metadata["georeference"];
  EXPECT_EQ(geo["epsg"], 32633);
  EXPECT_EQ(geo["model_pixel_scale"], nlohmann::json({10.0, 10.0, 0.0}));
  EXPECT_EQ(geo["model_tiepoint"], nlohmann::json({0, 0, 0, 500000.0, 6000000.0, 0}));
  EXPECT_EQ(geo["geo_key_directory"].size(), 16u);
  EXPECT_EQ(geo["geo_double_params"], nlohmann::json({6378137.0, 298.257223563}));
  EXPECT_EQ(geo["geo_ascii_params"], "WGS 84 / UTM zone 33N|");
  EXPECT_EQ(geo["gdal_nodata"], "0");
  EXPECT_THAT(geo["gdal_metadata"].get<std::string>(), HasSubstr("AREA"));
  EXPECT_FALSE(geo.contains("model_transformation"));
}

TEST(TiffReader, ExtractsGeographicEpsgAndTransformation) {
  TiffSpec spec{.width_px = 16, .height_px = 16, .samples = 3};
  spec.geo.model_transformation = {1, 0, 0, 10, 0, -1, 0, 50, 0, 0, 0, 0, 0, 0, 0, 1};
  spec.geo.geo_key_directory = {1, 1, 0, 2, 1024, 0, 1, 2, 2048, 0, 1, 4326};
  const std::string path = writeFixture(spec, "geographic.tif");
  auto reader = openTiffReader(path);
  ASSERT_TRUE(reader.has_value()) << reader.error().message;
  const nlohmann::json& geo = (*reader)->info().metadata["georeference"];
  EXPECT_EQ(geo["epsg"], 4326);
  EXPECT_EQ(geo["model_transformation"].size(), 16u);
}

TEST(TiffReader, PlainTiffHasNoGeoreference) {
  const std::string path = writeFixture(TiffSpec{.width_px = 8, .height_px = 8}, "plain.tif");
  auto reader = openTiffReader(path);
  ASSERT_TRUE(reader.has_value()) << reader.error().message;
  EXPECT_FALSE((*reader)->info().metadata.contains("georeference"));
  EXPECT_EQ((*reader)->info().metadata["tiff"]["compression"], "none");
}

struct RejectCase {
  const char* name;
  TiffSpec spec;
  const char* needle;
};

class TiffRejectTest : public ::testing::TestWithParam<RejectCase> {};

TEST_P(TiffRejectTest, RejectsUnsupportedSamples) {
  const RejectCase& c = GetParam();
  const std::string path = writeFixture(c.spec, std::string(c.name) + ".tif");
  auto reader = openTiffReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kUnsupported);
  EXPECT_THAT(reader.error().message, HasSubstr(std::string(c.name) + ".tif"));
  EXPECT_THAT(reader.error().message, HasSubstr(c.needle));
}

INSTANTIATE_TEST_SUITE_P(
    Unsupported, TiffRejectTest,
    ::testing::Values(
        RejectCase{"ThirtyTwoBitUnsigned",
                   {.width_px = 8,
                    .height_px = 8,
                    .samples = 1,
                    .bits = 32,
                    .photometric = PHOTOMETRIC_MINISBLACK},
                   "32-bit samples are not supported"},
        RejectCase{"Float64",
                   {.width_px = 8,
                    .height_px = 8,
                    .samples = 1,
                    .bits = 64,
                    .sample_format = SAMPLEFORMAT_IEEEFP,
                    .photometric = PHOTOMETRIC_MINISBLACK},
                   "64-bit floating-point"},
        RejectCase{"WideMinIsWhite",
                   {.width_px = 8,
                    .height_px = 8,
                    .samples = 1,
                    .bits = 16,
                    .photometric = PHOTOMETRIC_MINISWHITE},
                   "min-is-white"},
        RejectCase{"Signed",
                   {.width_px = 8,
                    .height_px = 8,
                    .samples = 1,
                    .sample_format = SAMPLEFORMAT_INT,
                    .photometric = PHOTOMETRIC_MINISBLACK},
                   "signed"},
        RejectCase{
            "Palette",
            {.width_px = 8, .height_px = 8, .samples = 1, .photometric = PHOTOMETRIC_PALETTE},
            "palette"},
        RejectCase{
            "Cmyk",
            {.width_px = 8, .height_px = 8, .samples = 4, .photometric = PHOTOMETRIC_SEPARATED},
            "CMYK"},
        RejectCase{"Lab",
                   {.width_px = 8, .height_px = 8, .samples = 3, .photometric = PHOTOMETRIC_CIELAB},
                   "L*a*b*"}),
    [](const ::testing::TestParamInfo<RejectCase>& param) {
      return std::string(param.param.name);
    });

// Wide samples come through unscaled: the fixture widens 8-bit value v to v * 257 (u16) and
// v / 255 (f32), and the reader must return exactly those, in every layout.
TEST(TiffReader, ReadsSixteenBitAndFloatSamplesAsTheyAre) {
  struct WideCase {
    const char* name;
    TiffSpec spec;
  };
  const WideCase cases[] = {
      {"u16-strips.tif", {.width_px = 19, .height_px = 11, .samples = 3, .bits = 16}},
      {"u16-tiles-alpha.tif",
       {.width_px = 19, .height_px = 21, .samples = 4, .bits = 16, .tiled = true}},
      {"u16-planar-deflate.tif",
       {.width_px = 19,
        .height_px = 11,
        .samples = 3,
        .bits = 16,
        .compression = COMPRESSION_ADOBE_DEFLATE,
        .planar = PLANARCONFIG_SEPARATE,
        .predictor = PREDICTOR_HORIZONTAL}},
      {"f32-gray.tif",
       {.width_px = 19,
        .height_px = 11,
        .samples = 1,
        .bits = 32,
        .sample_format = SAMPLEFORMAT_IEEEFP,
        .photometric = PHOTOMETRIC_MINISBLACK,
        .compression = COMPRESSION_ADOBE_DEFLATE}},
      {"f32-tiles-extra.tif",
       {.width_px = 19,
        .height_px = 21,
        .samples = 3,
        .bits = 32,
        .sample_format = SAMPLEFORMAT_IEEEFP,
        .photometric = PHOTOMETRIC_MINISBLACK,
        .tiled = true}},
  };
  for (const WideCase& c : cases) {
    SCOPED_TRACE(c.name);
    std::vector<uint8_t> pixels;
    const std::string path = writeFixture(c.spec, c.name, &pixels);
    SourceInfo info;
    const std::vector<uint8_t> got = readWhole(path, 5, &info);
    const bool is_float = c.spec.sample_format == SAMPLEFORMAT_IEEEFP;
    EXPECT_EQ(info.sample_type, is_float ? SampleType::kF32 : SampleType::kU16);
    const uint32_t channels = info.channels;
    EXPECT_EQ(channels, std::min<uint32_t>(c.spec.samples, is_float ? 2 : 4));
    const std::vector<uint8_t> expected8 = keepChannels(pixels, c.spec.samples, channels);
    ASSERT_EQ(got.size(), expected8.size() * (is_float ? 4 : 2));
    for (size_t i = 0; i < expected8.size(); ++i) {
      if (is_float) {
        float value;
        std::memcpy(&value, got.data() + 4 * i, 4);
        ASSERT_EQ(value, float(expected8[i]) / 255.0f) << i;
      } else {
        uint16_t value;
        std::memcpy(&value, got.data() + 2 * i, 2);
        ASSERT_EQ(value, expected8[i] * 257) << i;
      }
    }
  }
}

TEST(TiffReader, MissingFileIsNotFound) {
  const std::string path = test::testTempDir() + "absent.tif";
  auto reader = openTiffReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kNotFound);
  EXPECT_THAT(reader.error().message, HasSubstr("absent.tif"));
}

TEST(TiffReader, EmptyFileIsCorrupt) {
  const std::string path = test::testTempDir() + "empty.tif";
  ASSERT_TRUE(test::writeFileBytes(path, {}));
  auto reader = openTiffReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(reader.error().message, HasSubstr("empty.tif: empty file"));
}

TEST(TiffReader, RejectsNonTiff) {
  const std::string path = test::testTempDir() + "text.tif";
  ASSERT_TRUE(test::writeFileBytes(path, {'h', 'e', 'l', 'l', 'o', ' ', 'w', 'o', 'r', 'l', 'd'}));
  auto reader = openTiffReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(reader.error().message, HasSubstr("text.tif: not a readable TIFF"));
}

TEST(TiffReader, RejectsAbsurdDimensionsWithoutAllocating) {
  const std::string path = test::testTempDir() + "huge.tif";
  struct Case {
    uint32_t width, height;
    const char* size;
  };
  for (Case c : {Case{4000000000u, 16, "4000000000x16"}, Case{16, 100000000u, "16x100000000"},
                 Case{20000000u, 20000000u, "20000000x20000000"}}) {
    ASSERT_TRUE(test::writeFileBytes(path, test::makeRawTiffHeader(c.width, c.height, 64)));
    auto reader = openTiffReader(path);
    ASSERT_FALSE(reader.has_value());
    EXPECT_EQ(reader.error().code, ErrorCode::kTooLarge) << reader.error().message;
    EXPECT_THAT(reader.error().message, HasSubstr(std::string("huge.tif: image of ") + c.size));
  }
  // 4e9 rows in one strip overflow libtiff's own strip count, so libtiff refuses the
  // directory before our check; it must still fail cleanly and name the file.
  ASSERT_TRUE(test::writeFileBytes(path, test::makeRawTiffHeader(4000000000u, 4000000000u, 64)));
  auto reader = openTiffReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_THAT(reader.error().message, HasSubstr("huge.tif"));
}

TEST(TiffReader, RejectsZeroDimensions) {
  const std::string path = test::testTempDir() + "zero.tif";
  ASSERT_TRUE(test::writeFileBytes(path, test::makeRawTiffHeader(0, 16, 64)));
  auto reader = openTiffReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(reader.error().message, HasSubstr("zero.tif"));
}

TEST(TiffReader, ReadsHandMadeHeaderFixture) {
  const std::string path = test::testTempDir() + "raw.tif";
  ASSERT_TRUE(test::writeFileBytes(path, test::makeRawTiffHeader(8, 8, 64)));
  SourceInfo info;
  const std::vector<uint8_t> got = readWhole(path, 8, &info);
  EXPECT_EQ(got, std::vector<uint8_t>(64, 0x80));
}

TEST(TiffReader, TruncatedHeaderIsCorrupt) {
  const std::string source = writeFixture(TiffSpec{.width_px = 16, .height_px = 16}, "whole.tif");
  const std::vector<uint8_t> bytes = test::readFileBytes(source);
  // The directory sits after the pixel data in libtiff's files; a cut inside the header or
  // before the directory leaves no readable directory.
  for (size_t cut : {size_t(3), size_t(4), size_t(7), size_t(8), bytes.size() - 20}) {
    const std::string path = test::testTempDir() + "cut.tif";
    ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
    auto reader = openTiffReader(path);
    ASSERT_FALSE(reader.has_value()) << "cut at " << cut;
    EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt) << reader.error().message;
    EXPECT_THAT(reader.error().message, HasSubstr("cut.tif"));
  }
}

// A file whose pixel data is cut: libtiff writes the directory last, so this rewrites the
// fixture with the directory first by copying: simplest is to zero the strip byte range end.
TEST(TiffReader, TruncatedDataFailsOnTheRowWhereItHappens) {
  const std::string path = test::testTempDir() + "short.tif";
  // Hand-made: 16x16 gray, strip claims 256 bytes but the file holds 100.
  std::vector<uint8_t> bytes = test::makeRawTiffHeader(16, 16, 256);
  bytes.resize(bytes.size() - 156);
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
  auto reader = openTiffReader(path);
  if (!reader) {
    // libtiff may already refuse the strip size at open; that is fine if it names the file.
    EXPECT_THAT(reader.error().message, HasSubstr("short.tif"));
    return;
  }
  std::string error;
  const std::vector<uint8_t> got = test::readAllRows(**reader, 1, &error);
  EXPECT_THAT(error, HasSubstr("short.tif: row "));
  EXPECT_LE(got.size(), 100u);
}

// Every prefix of compressed striped, tiled and planar files: never a crash or an ASan report;
// each either fails naming the file or (when the cut only removed unused bytes) reads fully.
TEST(TiffReader, SurvivesEveryTruncation) {
  const TiffSpec specs[] = {
      {.width_px = 24,
       .height_px = 20,
       .samples = 3,
       .compression = COMPRESSION_ADOBE_DEFLATE,
       .rows_per_strip = 4},
      {.width_px = 24,
       .height_px = 20,
       .samples = 4,
       .compression = COMPRESSION_LZW,
       .planar = PLANARCONFIG_SEPARATE,
       .tiled = true},
      {.width_px = 24,
       .height_px = 20,
       .samples = 3,
       .compression = COMPRESSION_JPEG,
       .bigtiff = true,
       .rows_per_strip = 16},
  };
  const std::string dir = test::testTempDir();
  int index = 0;
  for (const TiffSpec& spec : specs) {
    const std::string source = dir + "source" + std::to_string(index++) + ".tif";
    ASSERT_EQ(test::writeTiff(source, spec, test::makeTestPixels(24, 20, spec.samples)), "");
    const std::vector<uint8_t> bytes = test::readFileBytes(source);
    for (size_t cut = 1; cut < bytes.size(); cut += 1 + cut / 64) {
      const std::string path = dir + "prefix.tif";
      ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
      auto reader = openTiffReader(path);
      if (!reader) {
        EXPECT_THAT(reader.error().message, HasSubstr("prefix.tif")) << "cut " << cut;
        continue;
      }
      std::string error;
      test::readAllRows(**reader, 3, &error);
      if (!error.empty()) {
        EXPECT_THAT(error, HasSubstr("prefix.tif")) << "cut " << cut;
      }
    }
  }
}

TEST(TiffReader, CorruptCompressedStripNamesTheRow) {
  TiffSpec spec{.width_px = 32,
                .height_px = 32,
                .samples = 3,
                .compression = COMPRESSION_ADOBE_DEFLATE,
                .rows_per_strip = 8};
  const std::string path = writeFixture(spec, "garbled.tif");
  auto reader0 = openTiffReader(path);
  ASSERT_TRUE(reader0.has_value());
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  // Strips follow the 8-byte header; overwrite the middle of the file's data with noise.
  for (size_t i = bytes.size() / 3; i < bytes.size() / 2; ++i) bytes[i] = uint8_t(i * 37 + 11);
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
  auto reader = openTiffReader(path);
  if (!reader) {
    EXPECT_THAT(reader.error().message, HasSubstr("garbled.tif"));
    return;
  }
  std::string error;
  test::readAllRows(**reader, 8, &error);
  EXPECT_THAT(error, HasSubstr("garbled.tif: row "));
}

}  // namespace
}  // namespace tessera::detail
