// comparePictures: exact PSNR figures, the largest and mean differences, size checks.
#include <tessera/render.h>

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

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
}  // namespace
}  // namespace tessera
