// 16-bit and float images end to end (docs/builder.md, "16-bit and float"): built from a
// RowSource or a TIFF, read back bit-exact in their own type, averaged in their own type with
// the documented NaN and infinity rules, and refused with codecs and options that cannot hold
// them.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <tiffio.h>

#include <tessera/archive.h>
#include <tessera/build.h>
#include <tessera/picture_file.h>

#include "builder/band_reader.h"
#include "builder/downsample.h"
#include "support/test_images.h"

namespace tessera {
namespace {

using ::testing::HasSubstr;

// Samples of a w x h x channels image of `type` as raw bytes: a ramp with noise, and for f32
// the special values NaN (with a payload), +-Inf, -0 and a denormal in the first row.
std::vector<uint8_t> makeSamples(uint32_t w, uint32_t h, uint32_t channels, SampleType type) {
  const size_t count = size_t(w) * h * channels;
  std::vector<uint8_t> bytes(count * sampleBytes(type));
  uint32_t random = 7;
  for (size_t i = 0; i < count; ++i) {
    random = random * 1664525u + 1013904223u;
    if (type == SampleType::kU16) {
      const uint16_t v = uint16_t(i * 37 + (random >> 26));
      std::memcpy(bytes.data() + 2 * i, &v, 2);
    } else {
      const float v = float(i) * 0.25f - 100.0f + float(random >> 28) * 1e-3f;
      std::memcpy(bytes.data() + 4 * i, &v, 4);
    }
  }
  if (type == SampleType::kF32 && count >= 5) {
    const uint32_t specials[] = {0x7FC0BEEFu, 0x7F800000u, 0xFF800000u, 0x80000000u, 1u};
    std::memcpy(bytes.data(), specials, sizeof(specials));
  }
  return bytes;
}

RowSource arraySource(const std::vector<uint8_t>& bytes, uint32_t w, uint32_t h, uint32_t channels,
                      SampleType type) {
  RowSource source;
  source.name = "array";
  source.width_px = w;
  source.height_px = h;
  source.channels = channels;
  source.sample_type = type;
  const size_t row_bytes = size_t(w) * channels * sampleBytes(type);
  source.read_rows = [&bytes, row_bytes](uint32_t first, uint32_t rows, std::span<uint8_t> out) {
    std::memcpy(out.data(), bytes.data() + first * row_bytes, rows * row_bytes);
    return Result<void>();
  };
  return source;
}

uint16_t fileMinorVersion(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  uint8_t header[12] = {};
  file.read(reinterpret_cast<char*>(header), sizeof(header));
  return uint16_t(header[10] | header[11] << 8);
}

TEST(SampleTypeBuild, WideArraysRoundTripBitExactThroughEveryLosslessCodec) {
  const std::string dir = test::testTempDir();
  const uint32_t w = 70, h = 45;
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      for (Codec codec : {Codec::kZdelta, Codec::kPng, Codec::kLz4}) {
        if (!codecSupportsSampleType(codec, type)) continue;
        SCOPED_TRACE(std::string(sampleTypeName(type)) + " x" + std::to_string(channels) + " " +
                     codecName(codec));
        const std::vector<uint8_t> bytes = makeSamples(w, h, channels, type);
        BuildOptions options;
        options.row_sources.push_back(arraySource(bytes, w, h, channels, type));
        options.output = dir + "wide.tess";
        options.codec = codec;
        options.tile_size_px = 64;
        options.border_px = 1;
        auto report = buildArchive(options);
        ASSERT_TRUE(report) << report.error().message;
        EXPECT_EQ(report->tiles_uniform, 0u);
        EXPECT_EQ(fileMinorVersion(options.output), kSampleTypeMinorVersion);
        auto archive = Archive::openFile(options.output);
        ASSERT_TRUE(archive) << archive.error().message;
        EXPECT_EQ((*archive)->images()[0].sample_type, type);
        auto region = (*archive)->readRegion(0, 0, {0, 0, w, h});
        ASSERT_TRUE(region) << region.error().message;
        EXPECT_EQ(region->sample_type, type);
        EXPECT_TRUE(region->texels == bytes);
        EXPECT_TRUE((*archive)->verify().ok());
        auto rgba = (*archive)->readRegionRgba(0, 0, {0, 0, w, h});
        ASSERT_FALSE(rgba);
        EXPECT_EQ(rgba.error().code, ErrorCode::kUnsupported);
      }
    }
  }
}

TEST(SampleTypeBuild, EightBitArchivesKeepTheirMinorVersion) {
  const std::string dir = test::testTempDir();
  const std::vector<uint8_t> bytes = makeSamples(20, 10, 3, SampleType::kU16);
  BuildOptions options;
  options.row_sources.push_back(arraySource(bytes, 40, 10, 3, SampleType::kU8));
  options.output = dir + "narrow.tess";
  options.codec = Codec::kZstd;
  options.tile_size_px = 64;
  ASSERT_TRUE(buildArchive(options));
  EXPECT_EQ(fileMinorVersion(options.output), 0u);
}

TEST(SampleTypeBuild, CodecsAndOptionsThatCannotHoldWideSamplesAreRefused) {
  const std::string dir = test::testTempDir();
  const std::vector<uint8_t> bytes = makeSamples(16, 16, 3, SampleType::kF32);
  struct Case {
    Codec codec;
    bool srgb;
    const char* message;
  };
  const Case cases[] = {
      {Codec::kJpeg, false, "array: f32 samples cannot be stored with --codec jpeg"},
      {Codec::kPng, false, "cannot be stored with --codec png"},
      {Codec::kZdelta, true, "--srgb averages 8-bit samples only"},
  };
  for (const Case& c : cases) {
    BuildOptions options;
    options.row_sources.push_back(arraySource(bytes, 16, 16, 3, SampleType::kF32));
    options.output = dir + "refused.tess";
    options.codec = c.codec;
    options.srgb_downsample = c.srgb;
    auto report = buildArchive(options);
    ASSERT_FALSE(report) << c.message;
    EXPECT_EQ(report.error().code, ErrorCode::kInvalidArgument);
    EXPECT_THAT(report.error().message, HasSubstr(c.message));
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

// The rules of docs/builder.md, "16-bit and float", one 2x2 block at a time.
float averageF32(float a, float b, float c, float d) {
  const float top[2] = {a, b}, bottom[2] = {c, d};
  float out = 0;
  detail::downsampleRowPairWide(reinterpret_cast<const uint8_t*>(top),
                                reinterpret_cast<const uint8_t*>(bottom), 2, 1, SampleType::kF32,
                                reinterpret_cast<uint8_t*>(&out));
  return out;
}

TEST(SampleTypeBuild, FloatAveragingIgnoresNanAndPropagatesInfinity) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(averageF32(1, 2, 3, 6), 3.0f);
  EXPECT_EQ(averageF32(1, nan, 2, 6), 3.0f);  // NaN left out: mean of three
  EXPECT_EQ(averageF32(nan, nan, nan, 5), 5.0f);
  EXPECT_EQ(averageF32(inf, 1, 2, 3), inf);
  EXPECT_EQ(averageF32(-inf, nan, 2, 3), -inf);
  EXPECT_TRUE(std::isnan(averageF32(inf, -inf, 2, 3)));
  // All NaN: the first sample's bits, payload included.
  float payload_nan;
  const uint32_t bits = 0x7FC0BEEFu;
  std::memcpy(&payload_nan, &bits, 4);
  const float all_nan = averageF32(payload_nan, nan, nan, nan);
  uint32_t got;
  std::memcpy(&got, &all_nan, 4);
  EXPECT_EQ(got, bits);
  // The mean is taken in double: a float sum of these would overflow to infinity.
  EXPECT_EQ(averageF32(3e38f, 3e38f, 3e38f, 3e38f), 3e38f);
}

TEST(SampleTypeBuild, SixteenBitAveragingIsTheRoundedMeanWeightedByAlpha) {
  auto average = [](std::vector<uint16_t> top, std::vector<uint16_t> bottom, uint32_t channels) {
    std::vector<uint16_t> out(channels);
    detail::downsampleRowPairWide(reinterpret_cast<const uint8_t*>(top.data()),
                                  reinterpret_cast<const uint8_t*>(bottom.data()), 2, channels,
                                  SampleType::kU16, reinterpret_cast<uint8_t*>(out.data()));
    return out;
  };
  EXPECT_EQ(average({65535, 65535}, {65534, 65534}, 1), (std::vector<uint16_t>{65535}));
  EXPECT_EQ(average({1, 2}, {2, 2}, 1), (std::vector<uint16_t>{2}));  // 7/4 rounds up
  // Gray + alpha: the transparent texel's gray does not count; alpha is the rounded mean.
  EXPECT_EQ(average({1000, 65535, 60000, 0}, {1000, 65535, 1000, 65535}, 2),
            (std::vector<uint16_t>{1000, 49151}));
  EXPECT_EQ(average({5, 0, 9, 0}, {7, 0, 3, 0}, 2), (std::vector<uint16_t>{0, 0}));
}

TEST(SampleTypeBuild, FloatTiffBuildsAndReadsBackExactly) {
  const std::string dir = test::testTempDir();
  const uint32_t w = 40, h = 30;
  const std::vector<uint8_t> pixels = test::makeTestPixels(w, h, 1);
  test::TiffSpec spec{.width_px = w,
                      .height_px = h,
                      .samples = 1,
                      .bits = 32,
                      .sample_format = SAMPLEFORMAT_IEEEFP,
                      .photometric = PHOTOMETRIC_MINISBLACK};
  ASSERT_EQ(test::writeTiff(dir + "dem.tif", spec, pixels), "");
  BuildOptions options;
  options.inputs = {dir + "dem.tif"};
  options.output = dir + "dem.tess";
  options.codec = Codec::kZdelta;
  options.tile_size_px = 64;
  ASSERT_TRUE(buildArchive(options));
  auto archive = Archive::openFile(options.output);
  ASSERT_TRUE(archive);
  auto region = (*archive)->readRegion(0, 0, {0, 0, w, h});
  ASSERT_TRUE(region);
  ASSERT_EQ(region->sample_type, SampleType::kF32);
  for (size_t i = 0; i < pixels.size(); ++i) {
    float value;
    std::memcpy(&value, region->texels.data() + 4 * i, 4);
    ASSERT_EQ(value, float(pixels[i]) / 255.0f) << i;
  }
}

// writeTiff (what `tessera extract -o X.tif` writes) read back by libtiff through the TIFF
// band reader: every sample type and channel count, bits unchanged.
TEST(SampleTypeBuild, TiffOutputReadsBackThroughLibtiffBitExact) {
  const std::string dir = test::testTempDir();
  for (SampleType type : {SampleType::kU8, SampleType::kU16, SampleType::kF32}) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(std::string(sampleTypeName(type)) + " x" + std::to_string(channels));
      Image image(13, 7, channels, type);
      image.texels = type == SampleType::kU8 ? test::makeTestPixels(13, 7, channels)
                                             : makeSamples(13, 7, channels, type);
      const std::string path = dir + "out.tif";
      ASSERT_TRUE(writeTiff(image, path));
      auto reader = detail::openTiffReader(path);
      ASSERT_TRUE(reader) << reader.error().message;
      EXPECT_EQ((*reader)->info().sample_type, type);
      EXPECT_EQ((*reader)->info().channels, channels);
      std::string error;
      EXPECT_TRUE(test::readAllRows(**reader, 3, &error) == image.texels) << error;
    }
  }
}

}  // namespace
}  // namespace tessera
