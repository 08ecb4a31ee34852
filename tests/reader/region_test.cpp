// Archive::readRegion and readRegionRgba: any rectangle of any level, inside, across tile
// edges, partly or wholly outside, equals the reference pyramid.
#include <tessera/archive.h>

#include <random>

#include <gtest/gtest.h>

#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera {
namespace {

struct RegionFixture {
  Image image;
  std::shared_ptr<Archive> archive;
};

RegionFixture buildFixture(uint32_t width, uint32_t height, uint32_t channels, uint32_t border) {
  RegionFixture fixture;
  fixture.image = test::makePatternImage(width, height, channels, 11 + channels);
  BuildOptions options;
  options.tile_size_px = 64;
  options.border_px = border;
  options.codec = Codec::kZstd;
  options.threads = 2;
  test::BuiltArchive built =
      test::buildFromImage(fixture.image, options, test::testTempDir(), "region.tess");
  auto archive = Archive::open(makeMemorySource(built.bytes, "region.tess"));
  EXPECT_TRUE(archive) << (archive ? "" : archive.error().message);
  if (archive) fixture.archive = *archive;
  return fixture;
}

class ReadRegion : public testing::TestWithParam<uint32_t> {};

TEST_P(ReadRegion, RandomRectanglesEqualTheReference) {
  const uint32_t channels = GetParam();
  RegionFixture fixture = buildFixture(300, 203, channels, channels == 2 ? 4 : 0);
  ASSERT_TRUE(fixture.archive);
  test::ReferencePyramid reference(fixture.image);
  std::mt19937 random(channels);
  const ImageInfo& info = fixture.archive->images()[0];
  for (uint32_t level = 0; level < info.level_count; ++level) {
    const int64_t w = info.levelWidthPx(level), h = info.levelHeightPx(level);
    for (int i = 0; i < 40; ++i) {
      int64_t x = std::uniform_int_distribution<int64_t>(-80, w + 10)(random);
      int64_t y = std::uniform_int_distribution<int64_t>(-80, h + 10)(random);
      uint32_t rw = std::uniform_int_distribution<uint32_t>(1, 200)(random);
      uint32_t rh = std::uniform_int_distribution<uint32_t>(1, 200)(random);
      auto region = fixture.archive->readRegion(0, level, {x, y, rw, rh});
      ASSERT_TRUE(region) << region.error().message;
      EXPECT_EQ(test::firstDifference(reference.region(level, x, y, rw, rh), *region), "")
          << "level " << level << " rect " << x << "," << y << " " << rw << "x" << rh;
    }
  }
}

TEST_P(ReadRegion, TheWholeLevelEqualsTheReferenceLevel) {
  const uint32_t channels = GetParam();
  RegionFixture fixture = buildFixture(300, 203, channels, 1);
  ASSERT_TRUE(fixture.archive);
  test::ReferencePyramid reference(fixture.image);
  const ImageInfo& info = fixture.archive->images()[0];
  for (uint32_t level = 0; level < info.level_count; ++level) {
    auto region = fixture.archive->readRegion(
        0, level, {0, 0, info.levelWidthPx(level), info.levelHeightPx(level)});
    ASSERT_TRUE(region) << region.error().message;
    EXPECT_EQ(test::firstDifference(reference.level(level), *region), "") << "level " << level;
  }
}

TEST_P(ReadRegion, RgbaExpandsChannelsAndMakesOutsideTransparent) {
  const uint32_t channels = GetParam();
  RegionFixture fixture = buildFixture(150, 70, channels, 0);
  ASSERT_TRUE(fixture.archive);
  const PixelRect rect{-3, -2, 160, 80};
  auto native = fixture.archive->readRegion(0, 0, rect);
  auto rgba = fixture.archive->readRegionRgba(0, 0, rect);
  ASSERT_TRUE(native);
  ASSERT_TRUE(rgba);
  ASSERT_EQ(rgba->channels, 4u);
  for (uint32_t y = 0; y < rect.height; ++y) {
    for (uint32_t x = 0; x < rect.width; ++x) {
      const uint8_t* s = native->row(y) + x * channels;
      const uint8_t* d = rgba->row(y) + x * 4;
      int64_t ix = rect.x + x, iy = rect.y + y;
      bool inside = ix >= 0 && iy >= 0 && ix < 150 && iy < 70;
      uint8_t expected[4];
      switch (channels) {
        case 1: expected[0] = expected[1] = expected[2] = s[0], expected[3] = 255; break;
        case 2: expected[0] = expected[1] = expected[2] = s[0], expected[3] = s[1]; break;
        case 3:
          expected[0] = s[0], expected[1] = s[1], expected[2] = s[2], expected[3] = 255;
          break;
        default: std::copy(s, s + 4, expected);
      }
      if (!inside) std::fill(expected, expected + 4, uint8_t(0));
      for (int c = 0; c < 4; ++c)
        ASSERT_EQ(d[c], expected[c]) << "(" << ix << "," << iy << ") channel " << c;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Channels, ReadRegion, testing::Values(1u, 2u, 3u, 4u));

TEST(ReadRegionErrors, RejectsBadImageLevelAndRectangles) {
  RegionFixture fixture = buildFixture(100, 100, 3, 0);
  ASSERT_TRUE(fixture.archive);
  const Archive& archive = *fixture.archive;
  auto no_image = archive.readRegion(1, 0, {0, 0, 1, 1});
  ASSERT_FALSE(no_image);
  EXPECT_EQ(no_image.error().code, ErrorCode::kInvalidArgument);
  auto no_level = archive.readRegion(0, 2, {0, 0, 1, 1});
  ASSERT_FALSE(no_level);
  EXPECT_EQ(no_level.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(no_level.error().message.find("region.tess"), std::string::npos);
  EXPECT_EQ(archive.readRegion(0, 0, {0, 0, 0, 5}).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(archive.readRegion(0, 0, {0, 0, 5, 0}).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(archive.readRegion(0, 0, {0, 0, 16385, 1}).error().code, ErrorCode::kTooLarge);
  EXPECT_EQ(archive.readRegionRgba(0, 0, {0, 0, 1, 16385}).error().code, ErrorCode::kTooLarge);
}

TEST(ReadRegionErrors, ARectangleFarOutsideIsAllZero) {
  RegionFixture fixture = buildFixture(100, 100, 4, 0);
  ASSERT_TRUE(fixture.archive);
  const PixelRect rects[] = {{-1000000, 0, 50, 50},
                             {100, 0, 50, 50},
                             {0, 100, 5, 5},
                             {INT64_MIN / 2, INT64_MAX / 2, 16, 16}};
  for (const PixelRect& rect : rects) {
    auto region = fixture.archive->readRegion(0, 0, rect);
    ASSERT_TRUE(region) << region.error().message;
    EXPECT_TRUE(std::all_of(region->texels.begin(), region->texels.end(),
                            [](uint8_t v) { return v == 0; }));
  }
}

TEST(ReadRegionErrors, AFailingTileFailsTheRegionNamingIt) {
  Image image = test::makePatternImage(200, 100, 3, 2);
  BuildOptions options;
  options.tile_size_px = 64;
  options.codec = Codec::kZstd;
  options.threads = 2;
  test::BuiltArchive built = test::buildFromImage(image, options, test::testTempDir());
  auto pristine = Archive::open(makeMemorySource(built.bytes, "r.tess"));
  ASSERT_TRUE(pristine);
  TileEntry entry = *(*pristine)->tileEntry({0, 0, 2, 0});
  ASSERT_EQ(entry.kind, TileKind::kEncoded);
  built.bytes[entry.offset_bytes] ^= 1;
  auto archive = Archive::open(makeMemorySource(built.bytes, "r.tess"));
  ASSERT_TRUE(archive);
  EXPECT_TRUE((*archive)->readRegion(0, 0, {0, 0, 128, 64}));  // tiles 0 and 1 only
  auto region = (*archive)->readRegion(0, 0, {100, 10, 50, 50});
  ASSERT_FALSE(region);
  EXPECT_NE(region.error().message.find("tile (0,2,0)"), std::string::npos)
      << region.error().message;
}

}  // namespace
}  // namespace tessera
