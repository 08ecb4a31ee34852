// comparePictures and writePng: exact PSNR figures, size checks, a libpng round trip and
// failed writes that leave nothing behind.
#include <tessera/render.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include <gtest/gtest.h>
#include <png.h>

#include "support/test_images.h"

namespace tessera {
namespace {

Picture gradient(uint32_t w, uint32_t h) {
  Picture picture{w, h, std::vector<uint8_t>(size_t(w) * h * 4)};
  for (size_t i = 0; i < picture.rgba.size(); ++i) picture.rgba[i] = uint8_t(i * 7 + (i >> 5));
  return picture;
}

TEST(RenderPicture, IdenticalPicturesHaveInfinitePsnr) {
  const Picture a = gradient(13, 7);
  Result<PictureDifference> d = comparePictures(a, a);
  ASSERT_TRUE(d) << d.error().message;
  EXPECT_EQ(d->psnr_db, std::numeric_limits<double>::infinity());
  EXPECT_EQ(d->max_abs, 0u);
  EXPECT_EQ(d->mean_abs, 0);
}

TEST(RenderPicture, OneChannelOffByOneGivesThePsnrFormula) {
  // 10 x 10 pixels, 400 samples, one off by 1: MSE = 1/400,
  // PSNR = 10 log10(255^2 * 400) = 74.1514 dB.
  const Picture a = gradient(10, 10);
  Picture b = a;
  b.rgba[123] = uint8_t(b.rgba[123] ^ 1);
  Result<PictureDifference> d = comparePictures(a, b);
  ASSERT_TRUE(d) << d.error().message;
  EXPECT_NEAR(d->psnr_db, 10 * std::log10(255.0 * 255.0 * 400), 1e-9);
  EXPECT_NEAR(d->psnr_db, 74.1514, 1e-4);
  EXPECT_EQ(d->max_abs, 1u);
  EXPECT_DOUBLE_EQ(d->mean_abs, 1.0 / 400);
}

TEST(RenderPicture, LargestAndMeanDifferenceOverAllChannels) {
  Picture a{2, 1, {0, 0, 0, 0, 0, 0, 0, 0}};
  Picture b{2, 1, {10, 0, 0, 0, 0, 0, 0, 255}};  // alpha counts like any channel
  Result<PictureDifference> d = comparePictures(a, b);
  ASSERT_TRUE(d) << d.error().message;
  EXPECT_EQ(d->max_abs, 255u);
  EXPECT_DOUBLE_EQ(d->mean_abs, 265.0 / 8);
  // MSE = (100 + 65025) / 8.
  EXPECT_NEAR(d->psnr_db, 10 * std::log10(65025.0 * 8 / 65125), 1e-9);
}

TEST(RenderPicture, SizeMismatchIsInvalidArgument) {
  Result<PictureDifference> d = comparePictures(gradient(4, 3), gradient(3, 4));
  ASSERT_FALSE(d);
  EXPECT_EQ(d.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(d.error().message.find("4x3"), std::string::npos) << d.error().message;
  Picture short_buffer = gradient(4, 3);
  short_buffer.rgba.pop_back();
  EXPECT_FALSE(comparePictures(gradient(4, 3), short_buffer));
}

/// Reads a PNG with libpng's simplified API as RGBA.
Picture readPngRgba(const std::string& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  Picture picture;
  if (!png_image_begin_read_from_file(&image, path.c_str())) {
    ADD_FAILURE() << path << ": " << image.message;
    return picture;
  }
  image.format = PNG_FORMAT_RGBA;
  picture.width = image.width;
  picture.height = image.height;
  picture.rgba.resize(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, picture.rgba.data(), 0, nullptr))
    ADD_FAILURE() << path << ": " << image.message;
  return picture;
}

TEST(RenderPicture, WritePngRoundTrips) {
  const std::string dir = test::testTempDir();
  const std::string path = dir + "shot.png";
  Picture picture = gradient(37, 23);
  picture.rgba[3] = 0;  // a transparent pixel keeps its colour bytes
  ASSERT_TRUE(writePng(picture, path));
  const Picture back = readPngRgba(path);
  EXPECT_EQ(back.width, 37u);
  EXPECT_EQ(back.height, 23u);
  EXPECT_EQ(back.rgba, picture.rgba);
  // Overwriting replaces the file; no temporary stays beside it.
  ASSERT_TRUE(writePng(gradient(5, 4), path));
  EXPECT_EQ(readPngRgba(path).width, 5u);
  size_t files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1u);
}

TEST(RenderPicture, WritePngToAMissingDirectoryFailsNamingThePath) {
  const std::string path = test::testTempDir() + "no/such/dir/shot.png";
  Result<void> written = writePng(gradient(4, 4), path);
  ASSERT_FALSE(written);
  EXPECT_EQ(written.error().code, ErrorCode::kIo);
  EXPECT_NE(written.error().message.find(path), std::string::npos) << written.error().message;
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(RenderPicture, FailedRenameLeavesNoFile) {
  // The target is a directory: the PNG is written, the rename fails, the temporary goes.
  const std::string dir = test::testTempDir();
  const std::string path = dir + "taken";
  std::filesystem::create_directory(path);
  Result<void> written = writePng(gradient(4, 4), path);
  ASSERT_FALSE(written);
  EXPECT_NE(written.error().message.find(path), std::string::npos) << written.error().message;
  size_t files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1u);  // only the directory
  EXPECT_TRUE(std::filesystem::is_directory(path));
}

TEST(RenderPicture, WritePngRejectsAnEmptyPicture) {
  const std::string path = test::testTempDir() + "empty.png";
  Result<void> written = writePng(Picture{}, path);
  ASSERT_FALSE(written);
  EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(path));
}

}  // namespace
}  // namespace tessera
