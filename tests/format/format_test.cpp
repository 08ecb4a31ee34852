// Geometry and names of the format vocabulary (docs/format.md, "Images" and "Levels").
#include <tessera/format.h>

#include <gtest/gtest.h>

namespace tessera {
namespace {

TEST(LevelCountFor, StopsAtTheFirstLevelThatFitsOneTile) {
  struct Case {
    uint32_t width, height, tile, levels;
  };
  const Case cases[] = {
      {1, 1, 64, 1},
      {64, 64, 64, 1},
      {65, 64, 64, 2},
      {64, 65, 64, 2},
      {128, 128, 64, 2},
      {129, 1, 64, 3},
      {1, 300, 64, 4},
      {300, 1, 2048, 1},
      {4097, 4095, 64, 8},
      {4097, 4095, 2048, 3},
      {4096, 4096, 2048, 2},
      {1000, 999, 256, 3},
      {1u << 24, 1u << 24, 64, 19},
      {1u << 24, 1, 2048, 14},
  };
  for (const Case& c : cases)
    EXPECT_EQ(levelCountFor(c.width, c.height, c.tile), c.levels)
        << c.width << "x" << c.height << " tile " << c.tile;
}

ImageInfo makeInfo(uint32_t width, uint32_t height, uint32_t tile, uint32_t border = 0) {
  ImageInfo info;
  info.width_px = width;
  info.height_px = height;
  info.channels = 3;
  info.tile_size_px = tile;
  info.border_px = border;
  info.level_count = levelCountFor(width, height, tile);
  return info;
}

TEST(ImageInfo, LevelSizesAreCeilingsOfPowersOfTwo) {
  ImageInfo info = makeInfo(1000, 999, 64);
  const uint32_t widths[] = {1000, 500, 250, 125, 63, 32, 16, 8, 4, 2, 1, 1};
  const uint32_t heights[] = {999, 500, 250, 125, 63, 32, 16, 8, 4, 2, 1, 1};
  for (uint32_t level = 0; level < 12; ++level) {
    EXPECT_EQ(info.levelWidthPx(level), widths[level]) << level;
    EXPECT_EQ(info.levelHeightPx(level), heights[level]) << level;
  }
  EXPECT_EQ(info.levelWidthPx(31), 1u);
  EXPECT_EQ(info.levelWidthPx(200), 1u);
  ImageInfo wide = makeInfo(kMaxImageSidePx, 3, 64);
  EXPECT_EQ(wide.levelWidthPx(24), 1u);
  EXPECT_EQ(wide.levelWidthPx(23), 2u);
}

TEST(ImageInfo, TilesCoverTheLevelWithPadding) {
  ImageInfo info = makeInfo(1000, 999, 256);
  EXPECT_EQ(info.tilesX(0), 4u);
  EXPECT_EQ(info.tilesY(0), 4u);
  EXPECT_EQ(info.tilesX(1), 2u);  // 500 px
  EXPECT_EQ(info.tilesX(2), 1u);  // 250 px
  ImageInfo exact = makeInfo(512, 256, 256);
  EXPECT_EQ(exact.tilesX(0), 2u);
  EXPECT_EQ(exact.tilesY(0), 1u);
  ImageInfo line = makeInfo(1, 300, 64);
  EXPECT_EQ(line.tilesX(0), 1u);
  EXPECT_EQ(line.tilesY(0), 5u);
}

TEST(ImageInfo, StoredTileIncludesBothBorders) {
  ImageInfo info = makeInfo(10, 10, 64, 4);
  info.channels = 2;
  EXPECT_EQ(info.storedTileSidePx(), 72u);
  EXPECT_EQ(info.storedTileBytes(), size_t(72) * 72 * 2);
}

TEST(CodecName, NamesEveryCodecAndParsesItBack) {
  const std::pair<Codec, const char*> names[] = {
      {Codec::kRaw, "raw"}, {Codec::kZstd, "zstd"}, {Codec::kLz4, "lz4"}, {Codec::kJpeg, "jpeg"},
      {Codec::kPng, "png"}, {Codec::kWebp, "webp"}, {Codec::kPtm, "ptm"},
  };
  for (const auto& [codec, name] : names) {
    EXPECT_STREQ(codecName(codec), name);
    Codec parsed = Codec::kRaw;
    ASSERT_TRUE(parseCodecName(name, &parsed)) << name;
    EXPECT_EQ(parsed, codec);
  }
  EXPECT_STREQ(codecName(Codec(200)), "unknown");
}

TEST(CodecName, RejectsUnknownAndMiscasedNames) {
  Codec codec = Codec::kLz4;
  EXPECT_FALSE(parseCodecName("ZSTD", &codec));
  EXPECT_FALSE(parseCodecName("", &codec));
  EXPECT_FALSE(parseCodecName("jpeg2000", &codec));
  EXPECT_EQ(codec, Codec::kLz4);
}

TEST(TileKindName, NamesEveryKind) {
  EXPECT_STREQ(tileKindName(TileKind::kEmpty), "empty");
  EXPECT_STREQ(tileKindName(TileKind::kUniform), "uniform");
  EXPECT_STREQ(tileKindName(TileKind::kEncoded), "encoded");
  EXPECT_STREQ(tileKindName(TileKind::kProcedural), "procedural");
}

}  // namespace
}  // namespace tessera
