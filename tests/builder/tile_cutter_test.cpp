// Cutting stored tiles: padding and borders replicate the level's edge texels.
#include "builder/tile_cutter.h"

#include <gtest/gtest.h>

#include "support/reference_pyramid.h"

namespace tessera::detail {
namespace {

class ImageRows final : public LevelRows {
 public:
  explicit ImageRows(const Image& image) : image_(image) {
    width_px = image.width_px;
    height_px = image.height_px;
    channels = image.channels;
  }
  const uint8_t* row(uint32_t y) const override {
    EXPECT_LT(y, height_px) << "cutTile asked for a row outside the level";
    return image_.row(y);
  }

 private:
  const Image& image_;
};

std::vector<uint8_t> cut(const Image& level, uint32_t tile, uint32_t border, uint32_t x,
                         uint32_t y) {
  ImageRows rows(level);
  uint32_t side = tile + 2 * border;
  std::vector<uint8_t> out(size_t(side) * side * level.channels, 0xCD);
  cutTile(rows, tile, border, x, y, out.data());
  return out;
}

Image grayLevel(uint32_t width, uint32_t height, std::vector<uint8_t> values) {
  Image image(width, height, 1);
  image.texels = std::move(values);
  return image;
}

TEST(TileCutter, ReplicatesEdgeTexelsIntoBorderAndPadding) {
  // Level 3 x 2: [1 2 3; 4 5 6]; tile 2 with border 1; tile (1, 0) covers x 1..4, y -1..2.
  Image level = grayLevel(3, 2, {1, 2, 3, 4, 5, 6});
  EXPECT_EQ(cut(level, 2, 1, 1, 0), (std::vector<uint8_t>{
                                        2, 3, 3, 3,  //
                                        2, 3, 3, 3,  //
                                        5, 6, 6, 6,  //
                                        5, 6, 6, 6,  //
                                    }));
  // Tile (0, 0) covers x -1..2: the left border copies column 0.
  EXPECT_EQ(cut(level, 2, 1, 0, 0), (std::vector<uint8_t>{
                                        1, 1, 2, 3,  //
                                        1, 1, 2, 3,  //
                                        4, 4, 5, 6,  //
                                        4, 4, 5, 6,  //
                                    }));
}

TEST(TileCutter, WithoutBorderAnInteriorTileIsACopy) {
  Image level = grayLevel(4, 4, {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15});
  EXPECT_EQ(cut(level, 2, 0, 1, 1), (std::vector<uint8_t>{10, 11, 14, 15}));
}

TEST(TileCutter, ASingleTexelFillsAWholeTileWithBorders) {
  Image level(1, 1, 3);
  level.texels = {9, 8, 7};
  std::vector<uint8_t> tile = cut(level, 64, 16, 0, 0);
  ASSERT_EQ(tile.size(), size_t(96) * 96 * 3);
  for (size_t i = 0; i < tile.size(); i += 3) {
    ASSERT_EQ(tile[i], 9);
    ASSERT_EQ(tile[i + 1], 8);
    ASSERT_EQ(tile[i + 2], 7);
  }
}

TEST(TileCutter, EqualsTheReferenceForEveryTileAndBorder) {
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    Image level = test::makePatternImage(37 + channels, 23, channels, channels);
    test::ReferencePyramid reference(level);
    for (uint32_t tile : {4u, 8u, 16u, 64u}) {
      for (uint32_t border : {0u, 1u, 3u, 16u}) {
        for (uint32_t y = 0; y < reference.tilesY(0, tile); ++y) {
          for (uint32_t x = 0; x < reference.tilesX(0, tile); ++x) {
            test::ReferenceTile expected = reference.tile(0, x, y, tile, border);
            ASSERT_EQ(cut(level, tile, border, x, y), expected.texels.texels)
                << channels << " channels, tile " << tile << " border " << border << " at (" << x
                << "," << y << ")";
          }
        }
      }
    }
  }
}

}  // namespace
}  // namespace tessera::detail
