// 2x2 box downsampling of a row pair: hand-computed blocks, odd edges, alpha weighting, sRGB,
// and agreement with the reference pyramid's downsampler on random rows.
#include "builder/downsample.h"

#include <random>

#include <gtest/gtest.h>

#include "support/reference_pyramid.h"

namespace tessera::detail {
namespace {

std::vector<uint8_t> downsample(const std::vector<uint8_t>& top, const std::vector<uint8_t>& bottom,
                                uint32_t width, uint32_t channels, bool srgb = false) {
  std::vector<uint8_t> out(size_t((width + 1) / 2) * channels, 0xCD);
  downsampleRowPair(top.data(), bottom.data(), width, channels, srgb, out.data());
  return out;
}

TEST(Downsample, AveragesEachBlockRoundingHalfUp) {
  // (10 + 20 + 30 + 41 + 2) / 4 = 25.75 -> 25; (1 + 1 + 1 + 2 + 2) / 4 = 1.75 -> 1;
  // (0 + 0 + 1 + 1 + 2) / 4 = 1; (255 * 4 + 2) / 4 = 255.
  EXPECT_EQ(downsample({10, 20, 1, 1, 0, 0, 255, 255}, {30, 41, 1, 2, 1, 1, 255, 255}, 8, 1),
            (std::vector<uint8_t>{25, 1, 1, 255}));
}

TEST(Downsample, AnOddLastColumnIsAveragedWithItself) {
  // Width 3: the last output texel is (2 * 9 + 2 * 100 + 2) / 4 = 55.
  EXPECT_EQ(downsample({0, 4, 9}, {8, 12, 100}, 3, 1), (std::vector<uint8_t>{6, 55}));
}

TEST(Downsample, AnOddLastRowIsTheSameRowTwice) {
  std::vector<uint8_t> row = {1, 2, 3, 200, 100, 7};
  // RGB, width 2: channels averaged independently.
  EXPECT_EQ(downsample(row, row, 2, 3), (std::vector<uint8_t>{101, 51, 5}));
}

TEST(Downsample, ASingleTexelStaysItself) {
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    std::vector<uint8_t> texel = {17, 99, 201, 255};
    texel.resize(channels);
    EXPECT_EQ(downsample(texel, texel, 1, channels), texel) << channels;
  }
}

TEST(Downsample, ColourIsWeightedByAlpha) {
  // Gray+alpha: one opaque 200, one transparent 100, two transparent 0. Colour ignores the
  // transparent texels: (200 * 255 + 255 / 2) / 255 = 200; alpha (255 + 2) / 4 = 64.
  EXPECT_EQ(downsample({200, 255, 100, 0}, {0, 0, 0, 0}, 2, 2), (std::vector<uint8_t>{200, 64}));
  // RGBA: alpha 255 and 85 -> A = 340; red (240 * 255 + 0 * 85 + 170) / 340 = 180.5 -> 180.
  EXPECT_EQ(downsample({240, 10, 20, 255, 0, 10, 200, 85}, {0, 0, 0, 0, 0, 0, 0, 0}, 2, 4),
            (std::vector<uint8_t>{180, 10, 65, 85}));
}

TEST(Downsample, AFullyTransparentBlockBecomesAllZero) {
  EXPECT_EQ(downsample({200, 0, 100, 0}, {50, 0, 9, 0}, 2, 2), (std::vector<uint8_t>{0, 0}));
  EXPECT_EQ(downsample({1, 2, 3, 0, 4, 5, 6, 0}, {7, 8, 9, 0, 10, 11, 12, 0}, 2, 4),
            (std::vector<uint8_t>{0, 0, 0, 0}));
}

TEST(Downsample, OpaqueAlphaRowsGiveThePlainMean) {
  EXPECT_EQ(downsample({10, 255, 21, 255}, {30, 255, 40, 255}, 2, 2),
            (std::vector<uint8_t>{25, 255}));
}

TEST(Downsample, SrgbAveragesInLinearLight) {
  // Black and white average to linear 0.5, which is sRGB 0.7354 -> 188 (IEC 61966-2-1), not 128.
  EXPECT_EQ(downsample({0, 255}, {0, 255}, 2, 1, true), (std::vector<uint8_t>{188}));
  EXPECT_EQ(downsample({0, 255}, {0, 255}, 2, 1, false), (std::vector<uint8_t>{128}));
}

TEST(Downsample, SrgbKeepsEveryUniformValue) {
  for (int v = 0; v < 256; ++v) {
    std::vector<uint8_t> row = {uint8_t(v), uint8_t(v), uint8_t(v), 255,
                                uint8_t(v), uint8_t(v), uint8_t(v), 255};
    EXPECT_EQ(downsample(row, row, 2, 4, true),
              (std::vector<uint8_t>{uint8_t(v), uint8_t(v), uint8_t(v), 255}))
        << v;
  }
}

TEST(Downsample, EqualsTheReferenceOnRandomRows) {
  std::mt19937 random(42);
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    for (uint32_t width : {1u, 2u, 3u, 7u, 64u, 255u}) {
      for (int trial = 0; trial < 20; ++trial) {
        Image pair(width, 2, channels);
        for (uint8_t& v : pair.texels) v = uint8_t(random());
        // Alpha drawn from {0, 255, anything} so both the opaque and weighted paths run.
        if (channels == 2 || channels == 4) {
          for (size_t i = channels - 1; i < pair.texels.size(); i += channels) {
            uint32_t pick = random() % 3;
            pair.texels[i] = pick == 0 ? 0 : pick == 1 ? 255 : pair.texels[i];
          }
          if (trial % 4 == 0)  // an all-opaque pair
            for (size_t i = channels - 1; i < pair.texels.size(); i += channels)
              pair.texels[i] = 255;
        }
        Image expected = test::referenceDownsample(pair);
        std::vector<uint8_t> actual(size_t(expected.width_px) * channels);
        downsampleRowPair(pair.row(0), pair.row(1), width, channels, false, actual.data());
        ASSERT_EQ(actual, expected.texels) << channels << " channels, width " << width;
      }
    }
  }
}

// The vector kernels against the scalar rule: every width from 1 to 300 (each kernel's block
// boundaries and scalar tails, odd last columns) and a few wide rows, rows at odd addresses,
// opaque and weighted alpha, with and without sRGB.
TEST(Downsample, VectorKernelsMatchTheScalarRuleBitForBit) {
  std::mt19937 random(20261128);
  std::vector<uint32_t> widths;
  for (uint32_t w = 1; w <= 300; ++w) widths.push_back(w);
  for (uint32_t w : {1023u, 1024u, 4097u}) widths.push_back(w);
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    for (uint32_t width : widths) {
      const size_t row_bytes = size_t(width) * channels;
      const uint32_t misalign = random() % 16;
      std::vector<uint8_t> rows(misalign + 2 * row_bytes);
      for (uint8_t& v : rows) v = uint8_t(random());
      uint8_t* top = rows.data() + misalign;
      uint8_t* bottom = top + row_bytes;
      const bool opaque = (channels == 2 || channels == 4) && random() % 2 == 0;
      if (opaque)
        for (size_t i = channels - 1; i < 2 * row_bytes; i += channels) top[i] = 255;
      for (bool srgb : {false, true}) {
        const size_t out_bytes = size_t((width + 1) / 2) * channels;
        std::vector<uint8_t> expected(out_bytes + 1, 0xA5), actual(out_bytes + 1, 0xA5);
        downsampleRowPairScalar(top, bottom, width, channels, srgb, expected.data());
        downsampleRowPair(top, bottom, width, channels, srgb, actual.data());
        ASSERT_EQ(actual, expected) << channels << " channels, width " << width << ", srgb " << srgb
                                    << ", opaque " << opaque;
        EXPECT_EQ(actual.back(), 0xA5) << "wrote past the row";
      }
    }
  }
}

}  // namespace
}  // namespace tessera::detail
