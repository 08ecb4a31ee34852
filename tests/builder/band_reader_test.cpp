#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "builder/band_reader.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using ::testing::HasSubstr;

TEST(BandReader, DispatchesOnContentNotExtension) {
  const std::string dir = test::testTempDir();
  const std::vector<uint8_t> pixels = test::makeTestPixels(8, 8, 3);
  ASSERT_EQ(test::writePng(dir + "really_png.tif", {.width_px = 8, .height_px = 8}, pixels), "");
  ASSERT_EQ(test::writeJpeg(dir + "really_jpeg.png", {.width_px = 8, .height_px = 8}, pixels), "");
  ASSERT_EQ(test::writeTiff(dir + "really_tiff.jpg", {.width_px = 8, .height_px = 8}, pixels), "");
  ASSERT_EQ(
      test::writeTiff(dir + "big.dat", {.width_px = 8, .height_px = 8, .bigtiff = true}, pixels),
      "");
  struct Case {
    const char* name;
    const char* format;
  };
  for (Case c : {Case{"really_png.tif", "png"}, Case{"really_jpeg.png", "jpeg"},
                 Case{"really_tiff.jpg", "tiff"}, Case{"big.dat", "tiff"}}) {
    auto reader = openBandReader(dir + c.name);
    ASSERT_TRUE(reader.has_value()) << reader.error().message;
    EXPECT_EQ((*reader)->info().format, c.format) << c.name;
  }
}

TEST(BandReader, OpensSyntheticSources) {
  auto reader = openBandReader("synthetic:300x200:5:3");
  ASSERT_TRUE(reader.has_value()) << reader.error().message;
  EXPECT_EQ((*reader)->info().format, "synthetic");
  EXPECT_EQ((*reader)->info().width_px, 300u);
  EXPECT_EQ((*reader)->info().height_px, 200u);
  EXPECT_EQ((*reader)->info().channels, 3u);
  auto bad = openBandReader("synthetic:300by200");
  ASSERT_FALSE(bad.has_value());
  EXPECT_EQ(bad.error().code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(bad.error().message, HasSubstr("synthetic:300by200"));
}

TEST(BandReader, MissingFileIsNotFound) {
  auto reader = openBandReader(test::testTempDir() + "nothing_here.tif");
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kNotFound);
  EXPECT_THAT(reader.error().message, HasSubstr("nothing_here.tif: no such file"));
}

TEST(BandReader, EmptyFileIsCorrupt) {
  const std::string path = test::testTempDir() + "zero_bytes.png";
  ASSERT_TRUE(test::writeFileBytes(path, {}));
  auto reader = openBandReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(reader.error().message, HasSubstr("zero_bytes.png: empty file"));
}

TEST(BandReader, UnknownContentIsUnsupported) {
  const std::string path = test::testTempDir() + "image.gif";
  ASSERT_TRUE(test::writeFileBytes(path, {'G', 'I', 'F', '8', '9', 'a', 1, 0, 1, 0}));
  auto reader = openBandReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kUnsupported);
  EXPECT_THAT(reader.error().message, HasSubstr("image.gif: not a TIFF, PNG or JPEG"));
  EXPECT_THAT(reader.error().message, HasSubstr("47 49 46"));
}

TEST(BandReader, ShortFileWithPartialMagicIsUnsupported) {
  const std::string path = test::testTempDir() + "stub.png";
  ASSERT_TRUE(test::writeFileBytes(path, {0x89, 'P'}));
  auto reader = openBandReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_THAT(reader.error().message, HasSubstr("stub.png"));
}

TEST(BandReader, DirectoryIsAnError) {
  const std::string dir = test::testTempDir();
  auto reader = openBandReader(dir);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kIo);
  EXPECT_THAT(reader.error().message, HasSubstr("is a directory"));
}

}  // namespace
}  // namespace tessera::detail
