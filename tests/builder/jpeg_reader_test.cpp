#include <cstdlib>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "builder/band_reader.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using test::JpegSpec;
using ::testing::HasSubstr;

// Mean and worst absolute difference between two equally sized images.
struct Difference {
  double mean = 0;
  int worst = 0;
};

Difference compare(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  Difference d;
  for (size_t i = 0; i < a.size(); ++i) {
    const int delta = std::abs(int(a[i]) - int(b[i]));
    d.mean += delta;
    d.worst = std::max(d.worst, delta);
  }
  d.mean /= double(std::max<size_t>(1, a.size()));
  return d;
}

std::string writeFixture(const JpegSpec& spec, const std::string& name,
                         std::vector<uint8_t>* pixels_out = nullptr) {
  const std::string path = test::testTempDir() + name;
  std::vector<uint8_t> pixels =
      test::makeTestPixels(spec.width_px, spec.height_px, spec.components);
  EXPECT_EQ(test::writeJpeg(path, spec, pixels), "");
  if (pixels_out) *pixels_out = std::move(pixels);
  return path;
}

TEST(JpegReader, ReadsGrayAndRgbWithinJpegError) {
  for (uint32_t components : {1u, 3u}) {
    for (bool progressive : {false, true}) {
      std::vector<uint8_t> pixels;
      const std::string path = writeFixture(
          {.width_px = 61, .height_px = 47, .components = components, .progressive = progressive},
          "photo.jpg", &pixels);
      auto reader = openJpegReader(path);
      ASSERT_TRUE(reader.has_value()) << reader.error().message;
      const SourceInfo& info = (*reader)->info();
      EXPECT_EQ(info.width_px, 61u);
      EXPECT_EQ(info.height_px, 47u);
      EXPECT_EQ(info.channels, components);
      EXPECT_EQ(info.format, "jpeg");
      EXPECT_EQ(info.metadata["jpeg"]["progressive"], progressive);
      EXPECT_GE(info.natural_band_rows, 8u);
      std::string error;
      const std::vector<uint8_t> got = test::readAllRows(**reader, 6, &error);
      EXPECT_EQ(error, "");
      ASSERT_EQ(got.size(), pixels.size());
      const Difference d = compare(got, pixels);
      EXPECT_LT(d.mean, 3.0) << components << " components";
      EXPECT_LT(d.worst, 40) << components << " components";
    }
  }
}

TEST(JpegReader, RejectsCmykJpeg) {
  const std::string path =
      writeFixture({.width_px = 16, .height_px = 16, .components = 4}, "cmyk.jpg");
  auto reader = openJpegReader(path);
  ASSERT_FALSE(reader.has_value());
  EXPECT_EQ(reader.error().code, ErrorCode::kUnsupported);
  EXPECT_THAT(reader.error().message, HasSubstr("cmyk.jpg: CMYK JPEG"));
}

TEST(JpegReader, MissingEmptyAndForeignFilesNameTheFile) {
  const std::string dir = test::testTempDir();
  auto missing = openJpegReader(dir + "none.jpg");
  ASSERT_FALSE(missing.has_value());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  EXPECT_THAT(missing.error().message, HasSubstr("none.jpg"));

  ASSERT_TRUE(test::writeFileBytes(dir + "empty.jpg", {}));
  auto empty = openJpegReader(dir + "empty.jpg");
  ASSERT_FALSE(empty.has_value());
  EXPECT_EQ(empty.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(empty.error().message, HasSubstr("empty.jpg: empty file"));

  ASSERT_TRUE(test::writeFileBytes(dir + "text.jpg", {'n', 'o', 't', ' ', 'j', 'p', 'e', 'g'}));
  auto foreign = openJpegReader(dir + "text.jpg");
  ASSERT_FALSE(foreign.has_value());
  EXPECT_EQ(foreign.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(foreign.error().message, HasSubstr("text.jpg"));
}

TEST(JpegReader, TruncatedHeaderIsCorrupt) {
  const std::vector<uint8_t> bytes =
      test::readFileBytes(writeFixture({.width_px = 16, .height_px = 16}, "whole.jpg"));
  for (size_t cut : {2, 3, 20, 100, 300}) {
    const std::string path = test::testTempDir() + "head.jpg";
    ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
    auto reader = openJpegReader(path);
    ASSERT_FALSE(reader.has_value()) << cut;
    EXPECT_EQ(reader.error().code, ErrorCode::kCorrupt);
    EXPECT_THAT(reader.error().message, HasSubstr("head.jpg"));
  }
}

TEST(JpegReader, TruncatedDataFailsOnTheRowWhereItHappens) {
  const std::vector<uint8_t> bytes =
      test::readFileBytes(writeFixture({.width_px = 64, .height_px = 128}, "tall.jpg"));
  for (double fraction : {0.3, 0.6, 0.95}) {
    const std::string path = test::testTempDir() + "cut.jpg";
    const size_t cut = size_t(double(bytes.size()) * fraction);
    ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
    auto reader = openJpegReader(path);
    ASSERT_TRUE(reader.has_value()) << reader.error().message;
    std::string error;
    const std::vector<uint8_t> got = test::readAllRows(**reader, 1, &error);
    EXPECT_THAT(error, HasSubstr("cut.jpg: row ")) << fraction;
    EXPECT_THAT(error, HasSubstr("Premature end")) << fraction;
    EXPECT_LT(got.size(), size_t(64 * 128 * 3));
    std::vector<uint8_t> row(64 * 3);
    EXPECT_FALSE((*reader)->readRows(1, row).has_value());
  }
}

TEST(JpegReader, ExtraneousBytesAreAnError) {
  std::vector<uint8_t> bytes =
      test::readFileBytes(writeFixture({.width_px = 32, .height_px = 32}, "clean.jpg"));
  // Garbage before the EOI marker: libjpeg warns "extraneous bytes before marker".
  bytes.insert(bytes.end() - 2, 64, 0x12);
  const std::string path = test::testTempDir() + "junk.jpg";
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
  auto reader = openJpegReader(path);
  ASSERT_TRUE(reader.has_value()) << reader.error().message;
  std::string error;
  test::readAllRows(**reader, 32, &error);
  EXPECT_THAT(error, HasSubstr("junk.jpg: after the last row"));
  EXPECT_THAT(error, HasSubstr("extraneous bytes"));
}

TEST(JpegReader, SurvivesEveryTruncation) {
  const std::string dir = test::testTempDir();
  for (bool progressive : {false, true}) {
    const std::string source = dir + "source.jpg";
    ASSERT_EQ(test::writeJpeg(source, {.width_px = 24, .height_px = 24, .progressive = progressive},
                              test::makeTestPixels(24, 24, 3)),
              "");
    const std::vector<uint8_t> bytes = test::readFileBytes(source);
    for (size_t cut = 1; cut < bytes.size(); cut += 1 + cut / 100) {
      const std::string path = dir + "prefix.jpg";
      ASSERT_TRUE(test::writeFileBytes(path, {bytes.begin(), bytes.begin() + long(cut)}));
      auto reader = openJpegReader(path);
      if (!reader) {
        EXPECT_THAT(reader.error().message, HasSubstr("prefix.jpg"));
        continue;
      }
      std::string error;
      test::readAllRows(**reader, 5, &error);
      // Every proper prefix lacks at least the EOI marker.
      EXPECT_THAT(error, HasSubstr("prefix.jpg: ")) << "cut " << cut;
    }
  }
}

}  // namespace
}  // namespace tessera::detail
