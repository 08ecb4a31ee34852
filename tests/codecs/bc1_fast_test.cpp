// The fast BC1 encoder: its payloads decode (decodeBc1Block, decodeTile) to what it was given
// within the limits of BC1, on flat colours, gradients, noise and photo-like tiles, at sizes that
// are not a multiple of 4, for grey, RGB and RGBA input; and it refuses what it cannot encode.
#include "codecs/bc1_fast.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include <gtest/gtest.h>

#include "bc/bc.h"
#include "codecs/encode.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

std::vector<uint8_t> encodeFast(const ImageView& tile) {
  std::vector<uint8_t> payload(bcPayloadBytes(Codec::kBc1, tile.width_px, tile.height_px));
  auto result = encodeBc1Fast(tile, payload);
  EXPECT_TRUE(result.has_value()) << result.error().message;
  return payload;
}

Image decodeBc1(std::span<const uint8_t> payload, uint32_t width, uint32_t height,
                uint32_t channels) {
  Image decoded(width, height, channels);
  auto result = decodeTile(Codec::kBc1, payload, decoded);
  EXPECT_TRUE(result.has_value()) << result.error().message;
  return decoded;
}

double psnr(const Image& a, const Image& b) {
  double sum = 0;
  for (size_t i = 0; i < a.texels.size(); ++i) {
    const double d = double(a.texels[i]) - double(b.texels[i]);
    sum += d * d;
  }
  const double mse = sum / double(a.texels.size());
  return mse == 0 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 / mse);
}

double fastPsnr(const Image& image) {
  return psnr(image,
              decodeBc1(encodeFast(image.view()), image.width_px, image.height_px, image.channels));
}

/// PSNR of libsquish's range fit (bc1 effort 1), the builder's fastest BC1 fit.
double squishRangeFitPsnr(const Image& image) {
  EncodeOptions options;
  options.effort = 1;
  auto payload = encodeTile(Codec::kBc1, image.view(), options);
  EXPECT_TRUE(payload.has_value()) << payload.error().message;
  return psnr(image, decodeBc1(*payload, image.width_px, image.height_px, image.channels));
}

Image gradient(uint32_t width, uint32_t height) {
  Image image(width, height, 3);
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x) {
      uint8_t* texel = image.row(y) + 3 * x;
      texel[0] = uint8_t(x * 255 / std::max(1u, width - 1));
      texel[1] = uint8_t(y * 255 / std::max(1u, height - 1));
      texel[2] = uint8_t((x + y) * 255 / std::max(1u, width + height - 2));
    }
  return image;
}

Image noise(uint32_t width, uint32_t height, uint32_t channels, uint32_t seed) {
  Image image(width, height, channels);
  for (uint8_t& sample : image.texels) sample = uint8_t(test::nextRandom(seed) >> 24);
  return image;
}

/// `image` padded to a multiple of 4 by repeating its last column and row (the stored layout).
Image padded(const Image& image) {
  Image out(bcBlocksAlong(image.width_px) * 4, bcBlocksAlong(image.height_px) * 4, image.channels);
  for (uint32_t y = 0; y < out.height_px; ++y)
    for (uint32_t x = 0; x < out.width_px; ++x)
      std::memcpy(out.row(y) + x * out.channels,
                  image.row(std::min(y, image.height_px - 1)) +
                      std::min(x, image.width_px - 1) * image.channels,
                  out.channels);
  return out;
}

TEST(Bc1Fast, FlatColoursComeBackWithinOneLevel) {
  // Every value of every channel, at sizes from one texel to several groups of four blocks.
  for (auto [w, h] : {std::pair{1u, 1u}, {3u, 5u}, {7u, 9u}, {20u, 8u}}) {
    for (uint32_t value = 0; value < 256; value += (w == 1 ? 1 : 37)) {
      Image image(w, h, 3);
      for (size_t i = 0; i < image.texels.size(); i += 3) {
        image.texels[i] = uint8_t(value);
        image.texels[i + 1] = uint8_t(255 - value);
        image.texels[i + 2] = uint8_t(value * 7);
      }
      const Image decoded = decodeBc1(encodeFast(image.view()), w, h, 3);
      for (size_t i = 0; i < image.texels.size(); ++i)
        ASSERT_LE(std::abs(int(decoded.texels[i]) - int(image.texels[i])), 1)
            << w << "x" << h << " value " << value << " sample " << i;
    }
  }
}

TEST(Bc1Fast, GradientsKeepTheirDetail) {
  for (auto [w, h] : {std::pair{64u, 64u}, {37u, 23u}}) {
    const Image image = gradient(w, h);
    // The 37x23 one climbs 7 levels a texel: BC1's four colours per block hold less.
    const double fast = fastPsnr(image);
    EXPECT_GT(fast, w == 64 ? 36.0 : 31.0) << w << "x" << h;
    EXPECT_GT(fast, squishRangeFitPsnr(image) - 1.0) << w << "x" << h;
  }
}

TEST(Bc1Fast, NoiseIsAsGoodAsSquishRangeFit) {
  // Noise has no axis to find: BC1 is poor at it, and the fast fit must not be much poorer.
  const Image image = noise(32, 32, 3, 7);
  EXPECT_GT(fastPsnr(image), squishRangeFitPsnr(image) - 1.0);
}

TEST(Bc1Fast, PhotoLikeTileMeetsTheTranscodeFloor) {
  // The 33 dB floor of issue 30 for a load-time transcode, and no worse than libsquish's fast
  // fit by more than half a decibel.
  Image image(256, 256, 3);
  image.texels = test::makeTestPixels(256, 256, 3, 3);
  const double fast = fastPsnr(image);
  EXPECT_GE(fast, 33.0);
  EXPECT_GT(fast, squishRangeFitPsnr(image) - 0.5);
}

TEST(Bc1Fast, EveryBlockDecodesOpaque) {
  // Four-colour blocks or one colour: never the three-colour mode's transparent index 3.
  for (const Image& image : {noise(24, 12, 3, 11), gradient(24, 12)}) {
    const std::vector<uint8_t> payload = encodeFast(image.view());
    for (size_t offset = 0; offset < payload.size(); offset += 8) {
      uint8_t rgba[64];
      decodeBc1Block(payload.data() + offset, rgba);
      for (uint32_t i = 0; i < 16; ++i) ASSERT_EQ(rgba[4 * i + 3], 255) << "block " << offset / 8;
    }
  }
}

TEST(Bc1Fast, EdgeTilesPadLikeTheStoredLayout) {
  // Sizes that are not a multiple of 4, across whole and partial groups of four blocks, encode
  // as their padded tile does, and decode to their own size.
  for (auto [w, h] : {std::pair{1u, 1u}, {5u, 7u}, {13u, 6u}, {17u, 3u}, {30u, 9u}}) {
    const Image image = noise(w, h, 3, w * 100 + h);
    const std::vector<uint8_t> payload = encodeFast(image.view());
    EXPECT_EQ(payload, encodeFast(padded(image).view())) << w << "x" << h;
    const Image decoded = decodeBc1(payload, w, h, 3);
    EXPECT_GT(psnr(image, decoded), squishRangeFitPsnr(image) - 1.0) << w << "x" << h;
  }
}

TEST(Bc1Fast, GreyIsSpreadToRgbAndAlphaIgnored) {
  const Image grey = noise(22, 10, 1, 5);
  Image grey_rgb(22, 10, 3), grey_alpha(22, 10, 2);
  for (size_t i = 0; i < grey.texels.size(); ++i) {
    std::memset(&grey_rgb.texels[3 * i], grey.texels[i], 3);
    grey_alpha.texels[2 * i] = grey.texels[i];
    grey_alpha.texels[2 * i + 1] = uint8_t(i);
  }
  const std::vector<uint8_t> payload = encodeFast(grey.view());
  EXPECT_EQ(payload, encodeFast(grey_rgb.view()));
  EXPECT_EQ(payload, encodeFast(grey_alpha.view()));
  EXPECT_GT(psnr(grey, decodeBc1(payload, 22, 10, 1)), 20.0);

  const Image rgb = noise(22, 10, 3, 6);
  Image rgba(22, 10, 4);
  for (size_t i = 0; i < size_t(22) * 10; ++i) {
    std::memcpy(&rgba.texels[4 * i], &rgb.texels[3 * i], 3);
    rgba.texels[4 * i + 3] = uint8_t(i * 3);
  }
  EXPECT_EQ(encodeFast(rgb.view()), encodeFast(rgba.view()));
}

TEST(Bc1Fast, StridedRowsEncodeAsPackedOnes) {
  const Image image = gradient(24, 8);
  std::vector<uint8_t> strided(size_t(24 * 3 + 5) * 8, 0xee);
  for (uint32_t y = 0; y < 8; ++y)
    std::memcpy(strided.data() + y * (24 * 3 + 5), image.row(y), 24 * 3);
  ImageView view = image.view();
  view.data = strided.data();
  view.stride_bytes = 24 * 3 + 5;
  EXPECT_EQ(encodeFast(view), encodeFast(image.view()));
}

TEST(Bc1Fast, RefusesWhatItCannotEncodeAndWritesNothing) {
  const Image image = gradient(8, 8);
  std::vector<uint8_t> payload(bcPayloadBytes(Codec::kBc1, 8, 8), 0x5a);
  const std::vector<uint8_t> untouched = payload;

  auto short_buffer = encodeBc1Fast(image.view(), std::span(payload).first(payload.size() - 1));
  ASSERT_FALSE(short_buffer.has_value());
  EXPECT_EQ(short_buffer.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(short_buffer.error().message.find("holds 31 bytes, 32 needed"), std::string::npos)
      << short_buffer.error().message;

  ImageView wide = image.view();
  wide.sample_type = SampleType::kU16;
  auto wide_result = encodeBc1Fast(wide, payload);
  ASSERT_FALSE(wide_result.has_value());
  EXPECT_EQ(wide_result.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(wide_result.error().message.find("8-bit only"), std::string::npos)
      << wide_result.error().message;

  ImageView empty = image.view();
  empty.width_px = 0;
  EXPECT_EQ(encodeBc1Fast(empty, payload).error().code, ErrorCode::kInvalidArgument);
  ImageView five = image.view();
  five.channels = 5;
  EXPECT_EQ(encodeBc1Fast(five, payload).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(payload, untouched);
}

}  // namespace
}  // namespace tessera::detail
