// writePng: a libpng round trip, errors naming the path, and no file left behind by a failed
// write.
#include <tessera/picture_file.h>

#include <sys/stat.h>

#include <filesystem>

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

TEST(PictureFile, WritePngRoundTrips) {
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

TEST(PictureFile, WritePngToAMissingDirectoryFailsNamingThePath) {
  const std::string path = test::testTempDir() + "no/such/dir/shot.png";
  Result<void> written = writePng(gradient(4, 4), path);
  ASSERT_FALSE(written);
  EXPECT_EQ(written.error().code, ErrorCode::kNotFound);
  EXPECT_NE(written.error().message.find(path), std::string::npos) << written.error().message;
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(PictureFile, FailedRenameLeavesNoFile) {
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

TEST(PictureFile, WritePngToAFifoIsRefusedAndKeepsTheFifo) {
  const std::string dir = test::testTempDir();
  const std::string path = dir + "pipe.png";
  ASSERT_EQ(::mkfifo(path.c_str(), 0644), 0);
  Result<void> written = writePng(gradient(4, 4), path);
  ASSERT_FALSE(written);
  EXPECT_NE(written.error().message.find(path + ": exists and is a FIFO"), std::string::npos)
      << written.error().message;
  struct stat st {};
  ASSERT_EQ(::lstat(path.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
}

TEST(PictureFile, WritePngRejectsAnEmptyPicture) {
  const std::string path = test::testTempDir() + "empty.png";
  Result<void> written = writePng(Picture{}, path);
  ASSERT_FALSE(written);
  EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(PictureFile, WritePngOfAnImageKeepsItsChannels) {
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    Image image(5, 3, channels);
    for (size_t i = 0; i < image.texels.size(); ++i) image.texels[i] = uint8_t(i * 7);
    const std::string path = test::testTempDir() + "image" + std::to_string(channels) + ".png";
    ASSERT_TRUE(writePng(image, path));
    std::FILE* file = std::fopen(path.c_str(), "rb");
    ASSERT_NE(file, nullptr);
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png_create_info_struct(png);
    png_init_io(png, file);
    png_read_info(png, info);
    EXPECT_EQ(png_get_channels(png, info), channels);
    EXPECT_EQ(png_get_image_width(png, info), 5u);
    std::vector<uint8_t> row(5 * channels);
    png_read_row(png, row.data(), nullptr);
    EXPECT_TRUE(std::equal(row.begin(), row.end(), image.texels.begin()));
    png_destroy_read_struct(&png, &info, nullptr);
    std::fclose(file);
  }
}

TEST(PictureFile, WritePngRejectsAnImageWhoseBytesDoNotMatchItsSize) {
  Image image(4, 4, 3);
  image.texels.pop_back();
  Result<void> written = writePng(image, test::testTempDir() + "short.png");
  ASSERT_FALSE(written);
  EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace tessera
