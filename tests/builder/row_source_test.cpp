// RowSource (tessera/build.h): an image the caller supplies row band by row band builds like a
// file (texels read back exactly with a lossless codec), bands are pulled top to bottom in
// tile rows, and a failing callback or a bad source fails the build naming it, leaving nothing.
#include <filesystem>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/build.h>

#include "support/test_images.h"

namespace tessera {
namespace {

/// A 150 x 100 RGB image whose texels are a function of their position.
uint8_t texel(uint32_t x, uint32_t y, uint32_t c) {
  return uint8_t(x * 7 + y * 13 + c * 101);
}

RowSource patternSource(std::vector<std::pair<uint32_t, uint32_t>>* calls) {
  RowSource source;
  source.name = "pattern";
  source.width_px = 150;
  source.height_px = 100;
  source.channels = 3;
  source.read_rows = [calls](uint32_t first_row, uint32_t rows, std::span<uint8_t> out) {
    calls->push_back({first_row, rows});
    for (uint32_t r = 0; r < rows; ++r)
      for (uint32_t x = 0; x < 150; ++x)
        for (uint32_t c = 0; c < 3; ++c)
          out[(size_t(r) * 150 + x) * 3 + c] = texel(x, first_row + r, c);
    return Result<void>();
  };
  return source;
}

TEST(RowSource, BuildsTheCallersTexelsBandByBand) {
  const std::string dir = test::testTempDir();
  std::vector<std::pair<uint32_t, uint32_t>> calls;
  BuildOptions options;
  options.row_sources.push_back(patternSource(&calls));
  options.output = dir + "rows.tess";
  options.codec = Codec::kPng;
  options.tile_size_px = 64;
  ASSERT_TRUE(buildArchive(options)) << "build failed";
  // One tile row per band, top to bottom, every row once.
  EXPECT_EQ(calls, (std::vector<std::pair<uint32_t, uint32_t>>{{0, 64}, {64, 36}}));

  auto archive = Archive::openFile(options.output);
  ASSERT_TRUE(archive) << archive.error().message;
  EXPECT_EQ((*archive)->images()[0].name, "pattern");
  auto region = (*archive)->readRegion(0, 0, {0, 0, 150, 100});
  ASSERT_TRUE(region) << region.error().message;
  for (uint32_t y = 0; y < 100; ++y)
    for (uint32_t x = 0; x < 150; ++x)
      for (uint32_t c = 0; c < 3; ++c)
        ASSERT_EQ(region->row(y)[x * 3 + c], texel(x, y, c)) << x << "," << y << "," << c;
}

TEST(RowSource, AFailingCallbackFailsTheBuildNamingTheSource) {
  const std::string dir = test::testTempDir();
  BuildOptions options;
  RowSource source;
  source.name = "camera";
  source.width_px = 64;
  source.height_px = 200;
  source.channels = 1;
  source.read_rows = [](uint32_t first_row, uint32_t, std::span<uint8_t>) -> Result<void> {
    if (first_row >= 64) return fail(ErrorCode::kIo, "sensor unplugged");
    return {};
  };
  options.row_sources.push_back(source);
  options.output = dir + "failed.tess";
  options.tile_size_px = 64;
  auto report = buildArchive(options);
  ASSERT_FALSE(report);
  EXPECT_EQ(report.error().code, ErrorCode::kIo);
  EXPECT_EQ(report.error().message, "camera: rows 64..127: sensor unplugged");
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

TEST(RowSource, BadSourcesAreRefusedBeforeAnyOutput) {
  const std::string dir = test::testTempDir();
  std::vector<std::pair<uint32_t, uint32_t>> calls;
  BuildOptions options;
  options.output = dir + "bad.tess";
  options.row_sources.push_back(patternSource(&calls));
  options.row_sources[0].read_rows = nullptr;
  EXPECT_EQ(buildArchive(options).error().message, "pattern: row source without a callback");
  options.row_sources[0] = patternSource(&calls);
  options.row_sources[0].channels = 5;
  EXPECT_EQ(buildArchive(options).error().message, "pattern: 5 channels out of 1..4");
  options.row_sources[0].channels = 3;
  options.row_sources[0].height_px = 0;
  auto zero = buildArchive(options);
  EXPECT_EQ(zero.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(zero.error().message.find("pattern: zero image dimensions"), std::string::npos);
  EXPECT_TRUE(calls.empty());
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

}  // namespace
}  // namespace tessera
