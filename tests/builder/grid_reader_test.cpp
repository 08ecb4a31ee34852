// Image grids ("grid:COLSxROWS:PATTERN"): a grid of PNGs builds the pixels of the stitched
// image, a missing or mismatched file is refused naming it, the reader opens one row of files
// at a time, and the parts of a split grid build merge into the single build.
#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/build.h>
#include <tessera/split_build.h>

#include "builder/band_reader.h"
#include "builder/grid_reader.h"
#include "support/test_images.h"

namespace tessera {
namespace {

constexpr uint32_t kColumns = 3, kRows = 2, kFileWidth = 70, kFileHeight = 90;

/// The stitched image's pixel: any function of x, y that differs between neighbours.
uint8_t texel(uint32_t x, uint32_t y, uint32_t c) {
  return uint8_t((x * 7 + y * 13 + c * 91 + (x * y) / 5) & 0xff);
}

/// Writes the grid's files (grid-c-r.png) and the stitched image (whole.png) into `dir`.
void writeGrid(const std::string& dir) {
  test::PngSpec spec;
  spec.width_px = kFileWidth;
  spec.height_px = kFileHeight;
  for (uint32_t r = 0; r < kRows; ++r) {
    for (uint32_t c = 0; c < kColumns; ++c) {
      std::vector<uint8_t> pixels;
      for (uint32_t y = 0; y < kFileHeight; ++y)
        for (uint32_t x = 0; x < kFileWidth; ++x)
          for (uint32_t ch = 0; ch < 3; ++ch)
            pixels.push_back(texel(c * kFileWidth + x, r * kFileHeight + y, ch));
      ASSERT_EQ(test::writePng(fmt::format("{}/grid-{}-{}.png", dir, c, r), spec, pixels), "");
    }
  }
  spec.width_px = kFileWidth * kColumns;
  spec.height_px = kFileHeight * kRows;
  std::vector<uint8_t> pixels;
  for (uint32_t y = 0; y < spec.height_px; ++y)
    for (uint32_t x = 0; x < spec.width_px; ++x)
      for (uint32_t ch = 0; ch < 3; ++ch) pixels.push_back(texel(x, y, ch));
  ASSERT_EQ(test::writePng(dir + "/whole.png", spec, pixels), "");
}

std::string gridInput(const std::string& dir) {
  return fmt::format("grid:{}x{}:{}/grid-{{col}}-{{row}}.png", kColumns, kRows, dir);
}

BuildOptions options(const std::string& input, const std::string& output) {
  BuildOptions build;
  build.inputs = {input};
  build.output = output;
  build.tile_size_px = 64;
  build.border_px = 1;
  build.codec = Codec::kZstd;  // lossless: the tiles compare texel for texel
  build.threads = 2;
  return build;
}

TEST(GridReader, BuildsThePixelsOfTheStitchedImage) {
  const std::string dir = test::testTempDir();
  writeGrid(dir);
  ASSERT_TRUE(buildArchive(options(gridInput(dir), dir + "/grid.tess")));
  ASSERT_TRUE(buildArchive(options(dir + "/whole.png", dir + "/whole.tess")));
  auto grid = Archive::openFile(dir + "/grid.tess");
  auto whole = Archive::openFile(dir + "/whole.tess");
  ASSERT_TRUE(grid && whole);
  const ImageInfo& info = (*grid)->images()[0];
  ASSERT_EQ(info.width_px, kFileWidth * kColumns);
  ASSERT_EQ(info.height_px, kFileHeight * kRows);
  for (uint32_t l = 0; l < info.level_count; ++l) {
    for (uint32_t y = 0; y < info.tilesY(l); ++y) {
      for (uint32_t x = 0; x < info.tilesX(l); ++x) {
        auto a = (*grid)->readTile({0, l, x, y});
        auto b = (*whole)->readTile({0, l, x, y});
        ASSERT_TRUE(a && b);
        EXPECT_TRUE(a->texels == b->texels) << "level " << l << " tile " << x << "," << y;
      }
    }
  }
}

TEST(GridReader, ReadsRowsOfFilesAndSkipsUnopened) {
  const std::string dir = test::testTempDir();
  writeGrid(dir);
  auto reader = detail::openGridReader(gridInput(dir));
  ASSERT_TRUE(reader) << reader.error().message;
  const detail::SourceInfo& info = (*reader)->info();
  const size_t row_bytes = size_t(info.width_px) * info.channels;
  // Past the first row of files without opening it, then two rows across the boundary.
  ASSERT_TRUE((*reader)->skipRows(kFileHeight - 1));
  std::vector<uint8_t> rows(2 * row_bytes);
  ASSERT_TRUE((*reader)->readRows(2, rows));
  for (uint32_t y = 0; y < 2; ++y)
    for (uint32_t x = 0; x < info.width_px; x += 17)
      EXPECT_EQ(rows[y * row_bytes + x * 3 + 1], texel(x, kFileHeight - 1 + y, 1)) << x << "," << y;
}

TEST(GridReader, RefusesMissingMismatchedFilesAndBadSpecs) {
  const std::string dir = test::testTempDir();
  writeGrid(dir);
  const std::string missing = dir + "/grid-2-1.png";
  std::filesystem::rename(missing, dir + "/aside.png");
  auto result = buildArchive(options(gridInput(dir), dir + "/out.tess"));
  ASSERT_FALSE(result);
  EXPECT_NE(result.error().message.find(missing), std::string::npos) << result.error().message;
  EXPECT_FALSE(std::filesystem::exists(dir + "/out.tess"));

  test::PngSpec spec;
  spec.width_px = kFileWidth - 1;
  spec.height_px = kFileHeight;
  ASSERT_EQ(test::writePng(missing, spec, std::vector<uint8_t>(spec.width_px * kFileHeight * 3)),
            "");
  result = buildArchive(options(gridInput(dir), dir + "/out.tess"));
  ASSERT_FALSE(result);
  EXPECT_NE(result.error().message.find(missing + ": 69x90 px"), std::string::npos)
      << result.error().message;
  EXPECT_FALSE(std::filesystem::exists(dir + "/out.tess"));

  for (const char* bad : {"grid:3x2:a.png", "grid:3:a{col}{row}.png", "grid:0x2:a{col}{row}",
                          "grid:3x2x:{col}{row}", "grid:x2:{col}{row}"})
    EXPECT_FALSE(detail::parseGridSpec(bad)) << bad;
  EXPECT_TRUE(detail::parseGridSpec("grid:3x2:d/{row}/{col}.tif"));
}

TEST(GridReader, SplitPartsMergeIntoTheSingleBuild) {
  const std::string dir = test::testTempDir();
  writeGrid(dir);
  const BuildOptions single = options(gridInput(dir), dir + "/single.tess");
  ASSERT_TRUE(buildArchive(single));
  std::vector<std::string> parts;
  for (uint32_t i = 1; i <= 3; ++i) {
    BuildOptions part = single;
    part.output = fmt::format("{}/part-{}.tess", dir, i);
    auto built = buildArchivePart(part, {i, 3});
    ASSERT_TRUE(built) << built.error().message;
    parts.push_back(part.output);
  }
  ASSERT_TRUE(mergeArchiveParts(parts, dir + "/merged.tess"));
  EXPECT_TRUE(test::readFileBytes(dir + "/single.tess") ==
              test::readFileBytes(dir + "/merged.tess"));
}

}  // namespace
}  // namespace tessera
