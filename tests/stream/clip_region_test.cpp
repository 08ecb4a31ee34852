// Clip-region arithmetic against Backes et al., section 5, with hand-worked cases: clip size
// (eq. 3), clip centre (eq. 4), the region around it, level choice (the exact texel-to-pixel
// form of eq. 5) and the start level (eq. 7).
#include <tessera/stream.h>

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace tessera {
namespace {

struct ClipCase {
  uint32_t screen_w, screen_h, tile_size_px;
  uint32_t expected_n;  // ceil(max(sw, sh) / t) * 2, worked by hand
};

TEST(ClipRegionTiles, MatchesEquationThreeForCommonScreensAndTileSizes) {
  const ClipCase cases[] = {
      // 1280x720: 1280/128 = 10, 1280/256 = 5, 1280/1024 = 1.25 -> 2.
      {1280, 720, 128, 20},
      {1280, 720, 256, 10},
      {1280, 720, 1024, 4},
      // 1920x1080: 1920/128 = 15, 1920/256 = 7.5 -> 8, 1920/1024 = 1.875 -> 2.
      {1920, 1080, 128, 30},
      {1920, 1080, 256, 16},
      {1920, 1080, 1024, 4},
      // 3840x2160: 3840/128 = 30, 3840/256 = 15, 3840/1024 = 3.75 -> 4.
      {3840, 2160, 128, 60},
      {3840, 2160, 256, 30},
      {3840, 2160, 1024, 8},
  };
  for (const ClipCase& c : cases)
    EXPECT_EQ(clipRegionTiles(c.screen_w, c.screen_h, c.tile_size_px), c.expected_n)
        << c.screen_w << "x" << c.screen_h << " at " << c.tile_size_px;
}

TEST(ClipRegionTiles, SquaredMatchesTheClipSizesOfBackesTableOne) {
  // Table 1 lists the clip size in nodes for 1024-px tiles: 16 (HD), 16 (FHD), 64 (UHD).
  auto nodes = [](uint32_t w, uint32_t h) {
    uint32_t n = clipRegionTiles(w, h, 1024);
    return n * n;
  };
  EXPECT_EQ(nodes(1280, 720), 16u);
  EXPECT_EQ(nodes(1920, 1080), 16u);
  EXPECT_EQ(nodes(3840, 2160), 64u);
}

TEST(ClipRegionTiles, UsesTheLongerSideWhateverTheOrientation) {
  EXPECT_EQ(clipRegionTiles(720, 1280, 256), clipRegionTiles(1280, 720, 256));
  EXPECT_EQ(clipRegionTiles(100, 1025, 256), 10u);  // 1025/256 = 4.004 -> 5
  EXPECT_EQ(clipRegionTiles(1024, 100, 256), 8u);   // exactly 4 tiles
}

TEST(ClipRegionTiles, ScreenSmallerThanATileStillGetsTwoTiles) {
  EXPECT_EQ(clipRegionTiles(100, 50, 256), 2u);
  EXPECT_EQ(clipRegionTiles(1, 1, 2048), 2u);
  EXPECT_EQ(clipRegionTiles(0, 0, 256), 2u);
}

TEST(ClipCentreTile, IsTheFloorOfPositionOverTileSize) {
  EXPECT_EQ(clipCentreTile(0, 256), 0);
  EXPECT_EQ(clipCentreTile(255.999, 256), 0);
  EXPECT_EQ(clipCentreTile(256, 256), 1);
  EXPECT_EQ(clipCentreTile(1000, 256), 3);  // 3.906
  EXPECT_EQ(clipCentreTile(1023.5, 1024), 0);
  EXPECT_EQ(clipCentreTile(1e9, 128), 7812500);
}

TEST(ClipCentreTile, RoundsNegativePositionsDownNotTowardsZero) {
  EXPECT_EQ(clipCentreTile(-0.5, 256), -1);
  EXPECT_EQ(clipCentreTile(-256, 256), -1);
  EXPECT_EQ(clipCentreTile(-256.5, 256), -2);
  EXPECT_EQ(clipCentreTile(-1000, 256), -4);  // -3.906
}

TEST(ClipRegionAround, SpansNTilesStartingHalfBeforeTheCentre) {
  EXPECT_EQ(clipRegionAround(10, 5, 16), (TileRect{2, -3, 18, 13}));
  EXPECT_EQ(clipRegionAround(0, 0, 2), (TileRect{-1, -1, 1, 1}));
  // Odd n: floor(n/2) tiles before the centre, the rest after it.
  EXPECT_EQ(clipRegionAround(10, 10, 5), (TileRect{8, 8, 13, 13}));
  EXPECT_EQ(clipRegionAround(-4, 7, 30), (TileRect{-19, -8, 11, 22}));
}

TEST(ClipRegionAround, ContainsItsCentreAndNSquaredTiles) {
  for (uint32_t n : {2u, 4u, 5u, 16u, 30u, 64u}) {
    TileRect r = clipRegionAround(3, -2, n);
    EXPECT_EQ(r.count(), int64_t(n) * n) << n;
    EXPECT_TRUE(r.contains(3, -2)) << n;
    EXPECT_FALSE(r.contains(3 + int64_t(n), -2)) << n;
  }
}

TEST(DesiredLevelFor, ExactPowersOfTwoSelectTheirLevel) {
  EXPECT_EQ(desiredLevelFor(1, 12), 0u);
  EXPECT_EQ(desiredLevelFor(2, 12), 1u);
  EXPECT_EQ(desiredLevelFor(4, 12), 2u);
  EXPECT_EQ(desiredLevelFor(8, 12), 3u);
  EXPECT_EQ(desiredLevelFor(1024, 12), 10u);
  // Computed rather than written, as a renderer would.
  EXPECT_EQ(desiredLevelFor(std::ldexp(1.0, 7), 12), 7u);
  EXPECT_EQ(desiredLevelFor(std::pow(2.0, 5.0), 12), 5u);
}

TEST(DesiredLevelFor, BetweenPowersTakesTheFinerLevel) {
  // The largest L with 2^L <= tpp: never magnify a coarser level while a finer one exists.
  EXPECT_EQ(desiredLevelFor(1.5, 12), 0u);
  EXPECT_EQ(desiredLevelFor(3, 12), 1u);
  EXPECT_EQ(desiredLevelFor(7.9, 12), 2u);
  EXPECT_EQ(desiredLevelFor(1000, 12), 9u);
}

TEST(DesiredLevelFor, MagnificationSelectsLevelZero) {
  EXPECT_EQ(desiredLevelFor(0.999, 12), 0u);
  EXPECT_EQ(desiredLevelFor(0.5, 12), 0u);
  EXPECT_EQ(desiredLevelFor(1.0 / 64, 12), 0u);
  EXPECT_EQ(desiredLevelFor(1e-300, 12), 0u);
}

TEST(DesiredLevelFor, HugeZoomOutClampsToTheCoarsestLevel) {
  EXPECT_EQ(desiredLevelFor(1e6, 8), 7u);
  EXPECT_EQ(desiredLevelFor(1e300, 8), 7u);
  EXPECT_EQ(desiredLevelFor(std::numeric_limits<double>::infinity(), 8), 7u);
  EXPECT_EQ(desiredLevelFor(4096, 1), 0u);  // a one-level image has nothing coarser
}

TEST(DesiredLevelFor, NanZeroAndNegativeSelectLevelZero) {
  EXPECT_EQ(desiredLevelFor(std::numeric_limits<double>::quiet_NaN(), 8), 0u);
  EXPECT_EQ(desiredLevelFor(0, 8), 0u);
  EXPECT_EQ(desiredLevelFor(-8, 8), 0u);
  EXPECT_EQ(desiredLevelFor(-std::numeric_limits<double>::infinity(), 8), 0u);
}

TEST(StartLevelFor, AddsLog2OfTheClipSize) {
  // Eq. 7 with level 0 the finest: a tile log2(n) levels coarser spans n tiles.
  EXPECT_EQ(startLevelFor(0, 16, 12), 4u);
  EXPECT_EQ(startLevelFor(3, 16, 12), 7u);
  EXPECT_EQ(startLevelFor(0, 4, 12), 2u);
  EXPECT_EQ(startLevelFor(0, 64, 12), 6u);
  EXPECT_EQ(startLevelFor(2, 2, 12), 3u);
  EXPECT_EQ(startLevelFor(5, 1, 12), 5u);
}

TEST(StartLevelFor, RoundsLog2UpForClipSizesThatAreNotPowersOfTwo) {
  // n = 30 (3840 px at 256): 2^5 = 32 >= 30 > 16 = 2^4.
  EXPECT_EQ(startLevelFor(0, 30, 12), 5u);
  EXPECT_EQ(startLevelFor(0, 10, 12), 4u);  // 16 >= 10 > 8
  EXPECT_EQ(startLevelFor(1, 60, 12), 7u);  // 64 >= 60 > 32
  EXPECT_EQ(startLevelFor(0, 17, 12), 5u);
}

TEST(StartLevelFor, OneStartTileSpansAtLeastTheClipRegion) {
  for (uint32_t n : {2u, 4u, 8u, 10u, 16u, 20u, 30u, 60u, 64u}) {
    uint32_t start = startLevelFor(0, n, 20);
    EXPECT_GE(uint64_t(1) << start, n) << n;
    EXPECT_LT(uint64_t(1) << (start - 1), n) << n;  // and it is the finest such level
  }
}

TEST(StartLevelFor, ClampsToTheCoarsestLevel) {
  EXPECT_EQ(startLevelFor(0, 16, 3), 2u);
  EXPECT_EQ(startLevelFor(6, 64, 8), 7u);
  EXPECT_EQ(startLevelFor(0, 1024, 1), 0u);
}

}  // namespace
}  // namespace tessera
