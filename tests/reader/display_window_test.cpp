// The display window: parsing of --window/--gamma and the server's query, resolution from an
// archive's statistics and percentiles, and the mapping to RGBA8 (NaN transparent).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include <gtest/gtest.h>

#include <tessera/build.h>
#include <tessera/byte_source.h>
#include <tessera/display_window.h>

#include "support/archive_fixture.h"
#include "support/test_images.h"
#include "support/wide_archive.h"

namespace tessera {
namespace {

TEST(DisplayWindowParse, TakesValuesPercentilesAndAuto) {
  DisplayWindowRequest request;
  ASSERT_TRUE(parseDisplayWindow("-2.5,1e3", request));
  EXPECT_EQ(request.kind, DisplayWindowRequest::Kind::kValues);
  EXPECT_EQ(request.first, -2.5);
  EXPECT_EQ(request.second, 1000);
  ASSERT_TRUE(parseDisplayWindow("p1,p99.5", request));
  EXPECT_EQ(request.kind, DisplayWindowRequest::Kind::kPercentiles);
  EXPECT_EQ(request.second, 99.5);
  ASSERT_TRUE(parseDisplayWindow("auto", request));
  EXPECT_EQ(request.kind, DisplayWindowRequest::Kind::kAuto);
}

TEST(DisplayWindowParse, RefusesMalformedWindowsNamingTheText) {
  for (const char* bad : {"", "5", "1,", ",1", "a,b", "3,3", "9,2", "p1,99", "p-1,p50", "p1,p101",
                          "1,inf", "nan,1", "1,2,3", " 1,2"}) {
    DisplayWindowRequest request;
    Result<void> parsed = parseDisplayWindow(bad, request);
    ASSERT_FALSE(parsed) << bad;
    EXPECT_EQ(parsed.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(parsed.error().message.find(std::string("'") + bad + "'"), std::string::npos)
        << parsed.error().message;
  }
  for (const char* bad : {"0", "-1", "x", "nan", "inf", ""}) EXPECT_FALSE(parseGamma(bad)) << bad;
  ASSERT_TRUE(parseGamma("2.2"));
  EXPECT_EQ(*parseGamma("2.2"), 2.2);
}

TEST(DisplayWindowMapping, FollowsTheFormulaAndShowsNanAsNoData) {
  const DisplayWindow window{100, 300, 2};
  EXPECT_EQ(windowSample(50, window), 0);
  EXPECT_EQ(windowSample(300, window), 255);
  EXPECT_EQ(windowSample(1e9, window), 255);
  EXPECT_EQ(windowSample(200, window), uint8_t(std::floor(0.25 * 255 + 0.5)));
  // f32 grey + alpha: colour windowed, alpha clamped, a NaN colour or alpha transparent.
  Image image(4, 1, 2, SampleType::kF32);
  const float samples[8] = {200, 0.5f, NAN, 1, 250, NAN, 300, 7};
  std::memcpy(image.texels.data(), samples, sizeof(samples));
  const Image rgba = windowToRgba8(image, window);
  ASSERT_EQ(rgba.channels, 4u);
  const uint8_t grey = windowSample(200, window);
  const std::vector<uint8_t> expected = {grey, grey, grey, 128, 0,   0,   0,   0,
                                         0,    0,    0,    0,   255, 255, 255, 255};
  EXPECT_EQ(rgba.texels, expected);
}

// A u16 and an f32 image; the f32 one has NaN in its top-left corner.
std::shared_ptr<Archive> buildRamp(SampleType type) {
  return test::buildWideArchive(test::testTempDir() + "window-" + sampleTypeName(type) + ".tess",
                                200, 120, 1, type, [type](uint32_t x, uint32_t y, uint32_t) {
                                  if (type == SampleType::kU16) return 1000.0 + x * 200 + y;
                                  return x < 8 && y < 8 ? double(NAN) : double(x) * 0.5 - 20.0;
                                });
}

// The finite samples of the finest level of at most 512 x 512 texels: here level 0.
std::vector<double> finiteSamples(const Archive& archive) {
  const ImageInfo& info = archive.images()[0];
  Image level = archive.readRegion(0, 0, {0, 0, info.width_px, info.height_px}).value();
  std::vector<double> values;
  for (size_t i = 0; i < size_t(info.width_px) * info.height_px; ++i) {
    double v;
    if (info.sample_type == SampleType::kU16) {
      uint16_t s;
      std::memcpy(&s, level.texels.data() + i * 2, 2);
      v = s;
    } else {
      float s;
      std::memcpy(&s, level.texels.data() + i * 4, 4);
      v = s;
    }
    if (std::isfinite(v)) values.push_back(v);
  }
  std::sort(values.begin(), values.end());
  return values;
}

TEST(DisplayWindowResolve, AutoTakesTheStatisticsAndPercentilesTheFiniteSamples) {
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    std::shared_ptr<Archive> archive = buildRamp(type);
    ASSERT_TRUE(archive);
    DisplayWindowRequest request;
    request.gamma = 1.5;
    Result<DisplayWindow> automatic = resolveDisplayWindow(*archive, 0, request);
    ASSERT_TRUE(automatic) << automatic.error().message;
    EXPECT_LT(automatic->low, automatic->high);
    EXPECT_EQ(automatic->gamma, 1.5);
    // The statistics come from the coarsest level, whose averages lie inside the samples.
    const std::vector<double> values = finiteSamples(*archive);
    EXPECT_GE(automatic->low, values.front()) << sampleTypeName(type);
    EXPECT_LE(automatic->high, values.back()) << sampleTypeName(type);

    ASSERT_TRUE(parseDisplayWindow("p0,p100", request));
    Result<DisplayWindow> extremes = resolveDisplayWindow(*archive, 0, request);
    ASSERT_TRUE(extremes) << extremes.error().message;
    EXPECT_EQ(extremes->low, values.front()) << "NaN never counts";
    EXPECT_EQ(extremes->high, values.back());
    ASSERT_TRUE(parseDisplayWindow("p25,p75", request));
    Result<DisplayWindow> middle = resolveDisplayWindow(*archive, 0, request);
    ASSERT_TRUE(middle);
    EXPECT_EQ(middle->low, values[size_t(std::llround(0.25 * double(values.size() - 1)))]);
    EXPECT_EQ(middle->high, values[size_t(std::llround(0.75 * double(values.size() - 1)))]);
  }
}

// The statistics are free-form metadata: an image entry, or its statistics, of another type
// is as good as none, and auto falls back to the percentiles (it threw before).
TEST(DisplayWindowResolve, AutoIgnoresStatisticsOfTheWrongType) {
  std::shared_ptr<Archive> built = buildRamp(SampleType::kU16);
  ASSERT_TRUE(built);
  std::vector<uint8_t> bytes(built->fileBytes());
  ASSERT_TRUE(built->source().read(0, bytes));
  DisplayWindowRequest percentiles;
  ASSERT_TRUE(parseDisplayWindow("p1,p99", percentiles));
  Result<DisplayWindow> expected = resolveDisplayWindow(*built, 0, percentiles);
  ASSERT_TRUE(expected) << expected.error().message;
  for (const char* metadata :
       {R"({"images":[5]})", R"({"images":["x"]})", R"({"images":[{"statistics":7}]})",
        R"({"images":[{"statistics":{"min":"a","max":{}}}]})"}) {
    Result<std::shared_ptr<Archive>> archive =
        Archive::open(makeMemorySource(test::withMetadata(bytes, metadata), "hostile.tess"));
    ASSERT_TRUE(archive) << archive.error().message;
    Result<DisplayWindow> automatic = resolveDisplayWindow(**archive, 0, DisplayWindowRequest{});
    ASSERT_TRUE(automatic) << metadata << ": " << automatic.error().message;
    EXPECT_EQ(automatic->low, expected->low) << metadata;
    EXPECT_EQ(automatic->high, expected->high) << metadata;
  }
}

}  // namespace
}  // namespace tessera
