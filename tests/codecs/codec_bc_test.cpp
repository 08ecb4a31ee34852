// bc1 and bc7: payload layout, padding, hand-built blocks decoded as the specifications say,
// quality and effort of the encoders, and refusal of what the codecs cannot hold.
#include "bc/bc.h"

#include <cmath>
#include <cstring>
#include <vector>

#include <gtest/gtest.h>

#include "codecs/encode.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

Image makePhotoLike(uint32_t width, uint32_t height, uint32_t channels, uint32_t seed = 1) {
  Image image(width, height, channels);
  image.texels = test::makeTestPixels(width, height, channels, seed);
  return image;
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

Image roundTrip(Codec codec, const Image& image, int effort = 0) {
  EncodeOptions options;
  options.effort = effort;
  auto payload = encodeTile(codec, image.view(), options);
  EXPECT_TRUE(payload.has_value()) << payload.error().message;
  EXPECT_EQ(payload->size(), bcPayloadBytes(codec, image.width_px, image.height_px));
  Image decoded(image.width_px, image.height_px, image.channels);
  auto result = decodeTile(codec, *payload, decoded);
  EXPECT_TRUE(result.has_value()) << result.error().message;
  return decoded;
}

TEST(BcCodec, PayloadIsOneBlockPerPaddedFourByFour) {
  EXPECT_EQ(bcPayloadBytes(Codec::kBc1, 258, 258), size_t(65 * 65 * 8));
  EXPECT_EQ(bcPayloadBytes(Codec::kBc7, 258, 258), size_t(65 * 65 * 16));
  EXPECT_EQ(bcPayloadBytes(Codec::kBc7, 1, 1), size_t(16));
  EXPECT_EQ(bcPayloadBytes(Codec::kBc1, 256, 256) * 8, size_t(256 * 256 * 4));
}

TEST(BcCodec, UniformTilesOfAnySizeRoundTripExactly) {
  // Colours each codec's endpoints hold exactly: bc1's 565 values widened; for bc7's mode 6,
  // channels of one parity, as the endpoint's p-bit is shared by its channels.
  for (Codec codec : {Codec::kBc1, Codec::kBc7}) {
    const uint8_t colour[3] = {255, uint8_t(codec == Codec::kBc1 ? 0 : 1),
                               uint8_t(codec == Codec::kBc1 ? 66 : 67)};
    for (uint32_t channels : {1u, 3u}) {
      for (auto [w, h] : {std::pair{1u, 1u}, {3u, 5u}, {7u, 9u}, {258u, 258u}}) {
        Image image(w, h, channels);
        for (size_t i = 0; i < image.texels.size(); ++i)
          image.texels[i] = channels == 1 ? 132 : colour[i % 3];
        SCOPED_TRACE(::testing::Message() << codecName(codec) << " " << w << "x" << h);
        EXPECT_EQ(roundTrip(codec, image).texels, image.texels);
      }
    }
  }
}

TEST(BcCodec, Bc1BlockDecodesAsTheSpecificationSays) {
  // Red and blue endpoints, four-colour mode (colour0 > colour1); texel i takes index i % 4.
  const uint8_t block[8] = {0x00, 0xF8, 0x1F, 0x00, 0xE4, 0xE4, 0xE4, 0xE4};
  uint8_t rgba[64];
  decodeBc1Block(block, rgba);
  const uint8_t expected[4][4] = {
      {255, 0, 0, 255}, {0, 0, 255, 255}, {170, 0, 85, 255}, {85, 0, 170, 255}};
  // 0xE4 = indices 0, 1, 2, 3 from the low bits.
  for (int i = 0; i < 16; ++i)
    EXPECT_EQ(std::memcmp(rgba + 4 * i, expected[i % 4], 4), 0) << "texel " << i;
  // Swapped endpoints select the three-colour mode: index 3 is transparent black.
  const uint8_t three[8] = {0x1F, 0x00, 0x00, 0xF8, 0xFF, 0xFF, 0xFF, 0xFF};
  decodeBc1Block(three, rgba);
  EXPECT_EQ(rgba[0] | rgba[1] | rgba[2] | rgba[3], 0);
}

TEST(BcCodec, Bc7Mode6BlockDecodesAsTheSpecificationSays) {
  // Endpoint 0 = (2*10+1, 2*20+1, 2*30+1, 2*127+1), endpoint 1 = (2*100, 2*110, 2*120, 2*127),
  // texel i has index i (the anchor's 3 bits hold 0).
  uint8_t block[16] = {};
  uint32_t position = 0;
  const auto put = [&](uint32_t value, uint32_t count) {
    for (uint32_t i = 0; i < count; ++i, ++position)
      block[position >> 3] |= uint8_t(((value >> i) & 1) << (position & 7));
  };
  put(0x40, 7);
  const uint32_t e0[4] = {10, 20, 30, 127}, e1[4] = {100, 110, 120, 127};
  for (int c = 0; c < 4; ++c) put(e0[c], 7), put(e1[c], 7);
  put(1, 1), put(0, 1);
  for (uint32_t i = 0; i < 16; ++i) put(i, i == 0 ? 3 : 4);
  ASSERT_EQ(position, 128u);
  uint8_t rgba[64];
  ASSERT_EQ(decodeBc7Block(block, rgba), 6);
  const uint32_t weights[16] = {0, 4, 9, 13, 17, 21, 26, 30, 34, 38, 43, 47, 51, 55, 60, 64};
  for (uint32_t i = 0; i < 16; ++i)
    for (uint32_t c = 0; c < 4; ++c) {
      const uint32_t a = e0[c] * 2 + 1, b = e1[c] * 2;
      EXPECT_EQ(rgba[4 * i + c], ((64 - weights[i]) * a + weights[i] * b + 32) >> 6)
          << "texel " << i << " channel " << c;
    }
}

TEST(BcCodec, PhotoLikeTilesKeepTheirDetail) {
  const Image rgb = makePhotoLike(64, 64, 3, 7), rgba = makePhotoLike(64, 64, 4, 7);
  // Thresholds well below the figures on real imagery (docs/codecs.md), above what a broken
  // fit (one colour per block) reaches on these gradients with noise.
  EXPECT_GT(psnr(rgb, roundTrip(Codec::kBc1, rgb)), 30.0);
  EXPECT_GT(psnr(rgb, roundTrip(Codec::kBc7, rgb)), 36.0);
  EXPECT_GT(psnr(rgba, roundTrip(Codec::kBc7, rgba)), 34.0);
}

TEST(BcCodec, Bc7EffortNeverLosesQuality) {
  const Image image = makePhotoLike(32, 32, 3, 3);
  double previous = 0;
  for (int effort = 1; effort <= 4; ++effort) {
    const double value = psnr(image, roundTrip(Codec::kBc7, image, effort));
    EXPECT_GE(value, previous) << "effort " << effort;
    previous = value;
  }
}

TEST(BcCodec, Bc7EncoderWritesMode6WithTheAnchorBitClear) {
  const Image image = makePhotoLike(16, 16, 4, 9);
  auto payload = encodeTile(Codec::kBc7, image.view(), {});
  ASSERT_TRUE(payload.has_value());
  for (size_t offset = 0; offset < payload->size(); offset += 16) {
    uint8_t rgba[64];
    EXPECT_EQ(decodeBc7Block(payload->data() + offset, rgba), 6) << "block at " << offset;
  }
}

TEST(BcCodec, RefusesWhatItCannotHold) {
  const Image rgba = makePhotoLike(8, 8, 4);
  auto bc1 = encodeTile(Codec::kBc1, rgba.view(), {});
  ASSERT_FALSE(bc1.has_value());
  EXPECT_EQ(bc1.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(bc1.error().message.find("bc7"), std::string::npos) << bc1.error().message;
  EXPECT_FALSE(codecSupportsSampleType(Codec::kBc7, SampleType::kU16));
  EXPECT_FALSE(codecIsLossless(Codec::kBc1));
  EXPECT_FALSE(codecIsLossless(Codec::kBc7));
}

TEST(BcCodec, DecoderRefusesOtherBc7ModesAndWrongSizes) {
  Image out(8, 8, 3);
  std::vector<uint8_t> payload(bcPayloadBytes(Codec::kBc7, 8, 8), 0);
  payload[0] = 0x40;   // a valid mode-6 block first
  payload[16] = 0x01;  // mode 0 in the second block
  auto result = decodeTile(Codec::kBc7, payload, out);
  ASSERT_FALSE(result.has_value());
  EXPECT_EQ(result.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(result.error().message.find("block (1, 0)"), std::string::npos)
      << result.error().message;
  for (Codec codec : {Codec::kBc1, Codec::kBc7}) {
    const size_t size = bcPayloadBytes(codec, 8, 8);
    for (size_t length : {size_t(0), size - 1, size + 1, size * 2}) {
      std::vector<uint8_t> wrong(length, 0x40);
      auto r = decodeTile(codec, wrong, out);
      ASSERT_FALSE(r.has_value()) << codecName(codec) << " " << length;
      EXPECT_EQ(r.error().code, ErrorCode::kCorrupt);
    }
  }
}

}  // namespace
}  // namespace tessera::detail
