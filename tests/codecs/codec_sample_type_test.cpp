// 16-bit and float tiles: which codecs store them, bit-exact round trips (NaN payloads,
// infinities and negative zero included) and hostile payloads (docs/codecs.md, "Sample types").
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "codecs/decode.h"
#include "codecs/encode.h"

namespace tessera::detail {
namespace {

constexpr Codec kAllCodecs[] = {Codec::kRaw, Codec::kZstd, Codec::kLz4, Codec::kJpeg,
                                Codec::kPng, Codec::kWebp, Codec::kPtm, Codec::kZdelta};

// A smooth field with a step and per-sample noise; float tiles also hold the special values
// (NaN with a payload, both infinities, negative zero, a denormal) that must survive exactly.
Image makeWideImage(uint32_t width, uint32_t height, uint32_t channels, SampleType type) {
  Image image(width, height, channels, type);
  uint32_t random = 12345;
  for (uint32_t y = 0; y < height; ++y) {
    for (uint32_t x = 0; x < width; ++x) {
      for (uint32_t c = 0; c < channels; ++c) {
        random = random * 1664525u + 1013904223u;
        const double field = 20000 + 9000 * std::sin(x * 0.05 + c) * std::cos(y * 0.04) +
                             (x > width / 2 ? 15000 : 0) + double(random >> 29);
        const size_t index = (size_t(y) * width + x) * channels + c;
        if (type == SampleType::kU16) {
          const uint16_t value = uint16_t(field);
          std::memcpy(image.texels.data() + index * 2, &value, 2);
        } else {
          float value = float(field / 1000.0 - 20.0);
          std::memcpy(image.texels.data() + index * 4, &value, 4);
        }
      }
    }
  }
  if (type == SampleType::kF32 && image.texels.size() >= 5 * 4) {
    const uint32_t specials[] = {0x7FC01234u, 0x7F800000u, 0xFF800000u, 0x80000000u, 0x00000001u};
    std::memcpy(image.texels.data(), specials, sizeof(specials));
  }
  return image;
}

Result<std::vector<uint8_t>> encode(Codec codec, const Image& image) {
  return encodeTile(codec, image.view(), {}, nullptr, nullptr);
}

TEST(CodecSampleType, SupportedCodecsRoundTripWideSamplesBitExact) {
  CodecScratch scratch;
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    for (Codec codec : kAllCodecs) {
      if (!codecSupportsSampleType(codec, type)) continue;
      for (uint32_t side : {1u, 5u, 66u}) {
        for (uint32_t channels = 1; channels <= 4; ++channels) {
          SCOPED_TRACE(std::string(codecName(codec)) + " " + sampleTypeName(type) + " " +
                       std::to_string(side) + "x" + std::to_string(channels));
          Image image = makeWideImage(side, side + 1, channels, type);
          auto payload = encodeTile(codec, image.view(), {}, nullptr, &scratch);
          ASSERT_TRUE(payload.has_value()) << payload.error().message;
          Image decoded(side, side + 1, channels, type);
          auto result = decodeTile(codec, *payload, decoded, nullptr, &scratch);
          ASSERT_TRUE(result.has_value()) << result.error().message;
          EXPECT_EQ(decoded.texels, image.texels);
        }
      }
    }
  }
}

TEST(CodecSampleType, CodecsThatCannotHoldASampleTypeRefuseItClearly) {
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    Image image = makeWideImage(8, 8, 3, type);
    for (Codec codec : {Codec::kJpeg, Codec::kWebp, Codec::kPtm}) {
      auto payload = encode(codec, image);
      ASSERT_FALSE(payload.has_value()) << codecName(codec);
      EXPECT_EQ(payload.error().code, ErrorCode::kUnsupported);
      EXPECT_NE(payload.error().message.find(sampleTypeName(type)), std::string::npos)
          << payload.error().message;
      Image decoded(8, 8, 3, type);
      std::vector<uint8_t> bytes(64, 0);
      auto result = decodeTile(codec, bytes, decoded);
      ASSERT_FALSE(result.has_value());
      EXPECT_EQ(result.error().code, ErrorCode::kUnsupported);
    }
  }
  auto png_float = encode(Codec::kPng, makeWideImage(8, 8, 1, SampleType::kF32));
  ASSERT_FALSE(png_float.has_value());
  EXPECT_EQ(png_float.error().code, ErrorCode::kUnsupported);
}

TEST(CodecSampleType, PngStoresSixteenBitSamplesAsSixteenBitPng) {
  Image image = makeWideImage(9, 7, 2, SampleType::kU16);
  auto payload = encode(Codec::kPng, image);
  ASSERT_TRUE(payload.has_value()) << payload.error().message;
  ASSERT_GT(payload->size(), 26u);
  EXPECT_EQ((*payload)[24], 16);  // IHDR bit depth
  // The same stream is not an 8-bit tile: the sample type is the archive's, not the stream's.
  Image narrow(9, 7, 2);
  auto result = decodeTile(Codec::kPng, *payload, narrow);
  ASSERT_FALSE(result.has_value());
  EXPECT_EQ(result.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(result.error().message.find("16-bit"), std::string::npos) << result.error().message;
}

TEST(CodecSampleType, ZdeltaBeatsPlainZstdOnSmoothWideSamples) {
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    Image image = makeWideImage(128, 128, 1, type);
    auto zdelta = encode(Codec::kZdelta, image);
    auto zstd = encode(Codec::kZstd, image);
    ASSERT_TRUE(zdelta.has_value() && zstd.has_value());
    EXPECT_LT(zdelta->size(), zstd->size()) << sampleTypeName(type);
  }
}

// Every truncation and every single-byte corruption of a wide zdelta or PNG-16 payload is
// rejected or decodes to a full tile; none crashes (the ASan build checks the bounds).
TEST(CodecSampleType, HostileWidePayloadsAreRejectedOrDecodeInBounds) {
  CodecScratch scratch;
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    for (Codec codec : {Codec::kZdelta, Codec::kPng}) {
      if (!codecSupportsSampleType(codec, type)) continue;
      SCOPED_TRACE(std::string(codecName(codec)) + " " + sampleTypeName(type));
      Image image = makeWideImage(12, 10, 3, type);
      auto payload = encode(codec, image);
      ASSERT_TRUE(payload.has_value());
      for (size_t n = 0; n < payload->size(); ++n) {
        Image decoded(12, 10, 3, type);
        std::vector<uint8_t> prefix(payload->begin(), payload->begin() + n);
        auto result = decodeTile(codec, prefix, decoded, nullptr, &scratch);
        ASSERT_FALSE(result.has_value()) << "prefix of " << n << " bytes";
        EXPECT_EQ(result.error().code, ErrorCode::kCorrupt);
      }
      for (size_t i = 0; i < payload->size(); ++i) {
        std::vector<uint8_t> corrupt = *payload;
        corrupt[i] ^= 0x5A;
        Image decoded(12, 10, 3, type);
        auto result = decodeTile(codec, corrupt, decoded, nullptr, &scratch);
        if (result) {
          EXPECT_EQ(decoded.texels.size(), image.texels.size());
        } else {
          EXPECT_EQ(result.error().code, ErrorCode::kCorrupt) << result.error().message;
        }
      }
    }
  }
}

TEST(CodecSampleType, SampleTypeNamesRoundTrip) {
  for (SampleType type : {SampleType::kU8, SampleType::kU16, SampleType::kF32}) {
    SampleType parsed = SampleType::kU8;
    ASSERT_TRUE(parseSampleTypeName(sampleTypeName(type), &parsed));
    EXPECT_EQ(parsed, type);
  }
  SampleType parsed = SampleType::kU8;
  EXPECT_FALSE(parseSampleTypeName("f64", &parsed));
  EXPECT_EQ(sampleBytes(SampleType::kU16), 2u);
  EXPECT_EQ(sampleBytes(SampleType::kF32), 4u);
}

}  // namespace
}  // namespace tessera::detail
