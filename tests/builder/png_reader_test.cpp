#include <cstring>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "builder/band_reader.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using test::PngColour;
using test::PngSpec;
using ::testing::HasSubstr;

std::string writeFixture(const PngSpec& spec, const std::string& name,
                         const std::vector<uint8_t>& pixels) {
  const std::string path = test::testTempDir() + name;
  EXPECT_EQ(test::writePng(path, spec, pixels), "");
  return path;
}

std::vector<uint8_t> readWhole(const std::string& path, SourceInfo* info) {
  auto reader = openPngReader(path);
  EXPECT_TRUE(reader.has_value()) << (reader ? "" : reader.error().message);
  if (!reader) return {};
  *info = (*reader)->info();
  std::string error;
  std::vector<uint8_t> out = test::readAllRows(**reader, 5, &error);
  EXPECT_EQ(error, "");
  return out;
}

TEST(PngReader, RoundTripsEightBitLayoutsExactly) {
  struct Case {
    PngColour colour;
    uint32_t channels;
  };
  for (Case c : {Case{PngColour::kGray, 1}, Case{PngColour::kGrayAlpha, 2},
                 Case{PngColour::kRgb, 3}, Case{PngColour::kRgba, 4}}) {
    const std::vector<uint8_t> pixels = test::makeTestPixels(37, 29, c.channels);
    const std::string path =
        writeFixture({.width_px = 37, .height_px = 29, .colour = c.colour}, "image.png", pixels);
    SourceInfo info;
    const std::vector<uint8_t> got = readWhole(path, &info);
    EXPECT_EQ(info.channels, c.channels);
    EXPECT_EQ(info.width_px, 37u);
    EXPECT_EQ(info.height_px, 29u);
    EXPECT_EQ(info.format, "png");
    EXPECT_TRUE(got == pixels) << "channels " << c.channels;
  }
}

TEST(PngReader, ExpandsPaletteToRgb) {
  std::vector<uint8_t> palette;
  for (int i = 0; i < 16; ++i)
    palette.insert(palette.end(), {uint8_t(i * 16), uint8_t(255 - i), uint8_t(i * 7)});
  std::vector<uint8_t> indices(20 * 10);
  for (size_t i = 0; i < indices.size(); ++i) indices[i] = uint8_t((i * 7) % 16);
  for (int depth : {4, 8}) {
    const std::string path = writeFixture({.width_px = 20,
                                           .height_px = 10,
                                           .colour = PngColour::kPalette,
                                           .bit_depth = depth,
                                           .palette = palette},
                                          "palette.png", indices);
    SourceInfo info;
    const std::vector<uint8_t> got = readWhole(path, &info);
    ASSERT_EQ(info.channels, 3u);
    std::vector<uint8_t> expected;
    for (uint8_t index : indices) {
      expected.insert(expected.end(), palette.begin() + index * 3, palette.begin() + index * 3 + 3);
    }
    EXPECT_TRUE(got == expected) << "depth " << depth;
  }
}

TEST(PngReader, ExpandsPaletteTransparencyToAlpha) {
  const std::vector<uint8_t> palette = {255, 0, 0, 0, 255, 0, 0, 0, 255};
  const std::vector<uint8_t> indices = {0, 1, 2, 2, 1, 0};
  const std::string path = writeFixture({.width_px = 3,
                                         .height_px = 2,
                                         .colour = PngColour::kPalette,
                                         .palette = palette,
                                         .transparency = {0, 128}},
                                        "trns.png", indices);
  SourceInfo info;
  const std::vector<uint8_t> got = readWhole(path, &info);
  ASSERT_EQ(info.channels, 4u);
  const std::vector<uint8_t> expected = {255, 0, 0,   0,   0, 255, 0, 128, 0,   0, 255, 255,
                                         0,   0, 255, 255, 0, 255, 0, 128, 255, 0, 0,   0};
  EXPECT_EQ(got, expected);
}

TEST(PngReader, ExpandsLowBitGrayToEightBits) {
  for (int depth : {1, 2, 4}) {
    const uint32_t max_value = (1u << depth) - 1;
    std::vector<uint8_t> values(16 * 3);
    for (size_t i = 0; i < values.size(); ++i) values[i] = uint8_t(i % (max_value + 1));
    const std::string path = writeFixture(
        {.width_px = 16, .height_px = 3, .colour = PngColour::kGray, .bit_depth = depth}, "low.png",
        values);
    SourceInfo info;
    const std::vector<uint8_t> got = readWhole(path, &info);
    ASSERT_EQ(info.channels, 1u);
    ASSERT_EQ(got.size(), values.size());
    for (size_t i = 0; i < values.size(); ++i) {
      EXPECT_EQ(got[i], values[i] * 255 / max_value) << "depth " << depth << " at " << i;
    }
  }
}

TEST(PngReader, TurnsRgbTransparencyIntoAlpha) {
  const std::vector<uint8_t> pixels = {10, 20, 30, 1, 2, 3, 10, 20, 30, 4, 5, 6};
  const std::string path = writeFixture(
      {.width_px = 2, .height_px = 2, .colour = PngColour::kRgb, .transparency = {10, 20, 30}},
      "rgbtrns.png", pixels);
  SourceInfo info;
  const std::vector<uint8_t> got = readWhole(path, &info);
  ASSERT_EQ(info.channels, 4u);
  EXPECT_EQ(got, (std::vector<uint8_t>{10, 20, 30, 0, 1, 2, 3, 255, 10, 20, 30, 0, 4, 5, 6, 255}));
}

// The fixture writes 8-bit value v as the 16-bit sample v * 257 (both bytes v).
TEST(PngReader, ReadsSixteenBitPngAsSixteenBitSamples) {
  const std::vector<uint8_t> pixels = test::makeTestPixels(5, 4, 3);
  const std::string path =
      writeFixture({.width_px = 5, .height_px = 4, .bit_depth = 16}, "deep.png", pixels);
  SourceInfo info;
  const std::vector<uint8_t> got = readWhole(path, &info);
  EXPECT_EQ(info.sample_type, SampleType::kU16);
  ASSERT_EQ(info.channels, 3u);
  ASSERT_EQ(got.size(), pixels.size() * 2);
  for (size_t i = 0; i < pixels.size(); ++i) {
    uint16_t value;
    std::memcpy(&value, got.data() + 2 * i, 2);
    ASSERT_EQ(value, pixels[i] * 257) << i;
  }
}

TEST(PngReader, RejectsInterlacedPng) {
  const std::string path = writeFixture({.width_px = 9, .height_px = 9, .interlaced = true},
                                        "adam7.png", test::makeTestPixels(9, 9, 3));
  auto reader = openPngReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kUnsupported);
  EXPECT_THAT(reader.error().message, HasSubstr("adam7.png: interlaced"));
}

TEST(PngReader, RejectsAbsurdDimensions) {
  const std::string path = test::testTempDir() + "wide.png";
  ASSERT_TRUE(test::writeFileBytes(path, test::makePngHeaderOnly(100000000, 10)));
  auto reader = openPngReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kTooLarge) << reader.error().message;
  EXPECT_THAT(reader.error().message, HasSubstr("wide.png"));
  // Over PNG's own 2^31-1 limit libpng refuses the header itself.
  ASSERT_TRUE(test::writeFileBytes(path, test::makePngHeaderOnly(4000000000u, 10)));
  auto invalid = openPngReader(path);
  ASSERT_FALSE(invalid.has_value());
  EXPECT_THAT(invalid.error().message, HasSubstr("wide.png"));
}

TEST(PngReader, RejectsZeroDimensions) {
  const std::string path = test::testTempDir() + "zero.png";
  ASSERT_TRUE(test::writeFileBytes(path, test::makePngHeaderOnly(0, 10)));
  auto reader = openPngReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(reader.error().message, HasSubstr("zero.png"));
}

TEST(PngReader, MissingEmptyAndForeignFilesNameTheFile) {
  const std::string dir = test::testTempDir();
  auto missing = openPngReader(dir + "none.png");
  ASSERT_FALSE(missing.has_value());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  EXPECT_THAT(missing.error().message, HasSubstr("none.png"));

  ASSERT_TRUE(test::writeFileBytes(dir + "empty.png", {}));
  auto empty = openPngReader(dir + "empty.png");
  ASSERT_FALSE(empty.has_value());
  EXPECT_EQ(empty.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(empty.error().message, HasSubstr("empty.png"));

  ASSERT_TRUE(test::writeFileBytes(dir + "gif.png", {'G', 'I', 'F', '8', '9', 'a', 0, 0, 0, 0}));
  auto foreign = openPngReader(dir + "gif.png");
  ASSERT_FALSE(foreign.has_value());
  EXPECT_EQ(foreign.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(foreign.error().message, HasSubstr("gif.png: not a PNG"));
}

TEST(PngReader, TruncatedHeaderIsCorrupt) {
  const std::string source =
      writeFixture({.width_px = 8, .height_px = 8}, "ok.png", test::makeTestPixels(8, 8, 3));
  const std::vector<uint8_t> bytes = test::readFileBytes(source);
  for (size_t cut : {4, 8, 12, 20, 30}) {
    const std::string path = test::testTempDir() + "head.png";
    ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
    auto reader = openPngReader(path);
    ASSERT_FALSE(reader.has_value()) << cut;
    EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt);
    EXPECT_THAT(reader.error().message, HasSubstr("head.png"));
  }
}

TEST(PngReader, TruncatedDataFailsOnTheRowWhereItHappens) {
  // Noise does not compress, so the IDAT data is spread evenly over the rows.
  std::vector<uint8_t> pixels(256 * 256 * 3);
  uint32_t state = 7;
  for (uint8_t& p : pixels) p = uint8_t((state = state * 1103515245u + 12345u) >> 24);
  const std::string source = writeFixture({.width_px = 256, .height_px = 256}, "noise.png", pixels);
  const std::vector<uint8_t> bytes = test::readFileBytes(source);
  for (double fraction : {0.25, 0.5, 0.9}) {
    const std::string path = test::testTempDir() + "cut.png";
    const size_t cut = size_t(double(bytes.size()) * fraction);
    ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
    auto reader = openPngReader(path);
    ASSERT_TRUE(reader.has_value()) << reader.error().message;
    std::string error;
    const std::vector<uint8_t> got = test::readAllRows(**reader, 1, &error);
    EXPECT_THAT(error, HasSubstr("cut.png: row ")) << fraction;
    // libpng reads IDAT in 8 KiB pieces: the failing row is at most that far before the cut.
    const double rows_read = double(got.size() / (256 * 3));
    EXPECT_LE(rows_read, 256 * fraction + 1) << error;
    EXPECT_GE(rows_read, 256 * fraction - 12) << error;
    EXPECT_TRUE(std::equal(got.begin(), got.end(), pixels.begin()));
    // A failed reader keeps failing rather than touching libpng again.
    if (rows_read < 256) {
      std::vector<uint8_t> row(256 * 3);
      EXPECT_FALSE((*reader)->readRows(1, row).has_value());
    }
  }
}

TEST(PngReader, SurvivesEveryTruncation) {
  const std::string dir = test::testTempDir();
  const std::string source = dir + "source.png";
  ASSERT_EQ(test::writePng(source, {.width_px = 20, .height_px = 12, .colour = PngColour::kRgba},
                           test::makeTestPixels(20, 12, 4)),
            "");
  const std::vector<uint8_t> bytes = test::readFileBytes(source);
  for (size_t cut = 1; cut < bytes.size(); ++cut) {
    const std::string path = dir + "prefix.png";
    ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
    auto reader = openPngReader(path);
    if (!reader) {
      EXPECT_THAT(reader.error().message, HasSubstr("prefix.png"));
      continue;
    }
    std::string error;
    test::readAllRows(**reader, 4, &error);
    if (!error.empty()) {
      EXPECT_THAT(error, HasSubstr("prefix.png: "));
    }
  }
}

TEST(PngReader, CorruptDataCrcIsAnError) {
  const std::vector<uint8_t> pixels = test::makeTestPixels(32, 32, 3);
  const std::string path = writeFixture({.width_px = 32, .height_px = 32}, "crc.png", pixels);
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  bytes[bytes.size() / 2] ^= 0x5a;  // inside IDAT
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
  auto reader = openPngReader(path);
  ASSERT_TRUE(reader.has_value());
  std::string error;
  test::readAllRows(**reader, 32, &error);
  EXPECT_THAT(error, HasSubstr("crc.png: row "));
}

}  // namespace
}  // namespace tessera::detail
