// Payload clustering orders: the Hilbert index and the three tile orders.
#include "format/tile_order.h"

#include <map>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

TEST(HilbertIndex, FirstOrderCurveVisitsTheQuadrantsInOrder) {
  // The order-1 curve: (0,0) -> (0,1) -> (1,1) -> (1,0).
  EXPECT_EQ(hilbertIndex(1, 0, 0), 0u);
  EXPECT_EQ(hilbertIndex(1, 0, 1), 1u);
  EXPECT_EQ(hilbertIndex(1, 1, 1), 2u);
  EXPECT_EQ(hilbertIndex(1, 1, 0), 3u);
}

TEST(HilbertIndex, ZeroBitsMapsTheOnlyCellToZero) {
  EXPECT_EQ(hilbertIndex(0, 0, 0), 0u);
}

TEST(HilbertIndex, IsABijectionWhoseConsecutiveCellsAreFourNeighbours) {
  for (uint32_t bits = 1; bits <= 7; ++bits) {
    const uint32_t side = 1u << bits;
    const uint64_t cells = uint64_t(side) * side;
    std::vector<int64_t> x_of(cells, -1), y_of(cells, -1);
    for (uint32_t y = 0; y < side; ++y) {
      for (uint32_t x = 0; x < side; ++x) {
        uint64_t d = hilbertIndex(bits, x, y);
        ASSERT_LT(d, cells) << bits << ": (" << x << "," << y << ")";
        ASSERT_EQ(x_of[d], -1) << bits << ": index " << d << " used twice";
        x_of[d] = x;
        y_of[d] = y;
      }
    }
    EXPECT_EQ(x_of[0], 0);
    EXPECT_EQ(y_of[0], 0);
    for (uint64_t d = 1; d < cells; ++d) {
      int64_t step = std::abs(x_of[d] - x_of[d - 1]) + std::abs(y_of[d] - y_of[d - 1]);
      ASSERT_EQ(step, 1) << bits << ": index " << d;
    }
  }
}

TEST(HilbertIndex, EachQuadrantIsOneContiguousQuarterOfTheCurve) {
  const uint32_t bits = 5, side = 32, quarter = side * side / 4;
  for (uint32_t qy = 0; qy < 2; ++qy) {
    for (uint32_t qx = 0; qx < 2; ++qx) {
      uint64_t low = ~0ull, high = 0;
      for (uint32_t y = qy * 16; y < qy * 16 + 16; ++y) {
        for (uint32_t x = qx * 16; x < qx * 16 + 16; ++x) {
          low = std::min(low, hilbertIndex(bits, x, y));
          high = std::max(high, hilbertIndex(bits, x, y));
        }
      }
      EXPECT_EQ(high - low + 1, quarter);
      EXPECT_EQ(low % quarter, 0u);
    }
  }
}

ImageInfo makeInfo(uint32_t width, uint32_t height, uint32_t tile) {
  ImageInfo info;
  info.width_px = width;
  info.height_px = height;
  info.channels = 3;
  info.tile_size_px = tile;
  info.level_count = levelCountFor(width, height, tile);
  return info;
}

using Key = std::tuple<uint32_t, uint32_t, uint32_t>;  // level, x, y

std::map<Key, size_t> positions(const std::vector<TileId>& order) {
  std::map<Key, size_t> out;
  for (size_t i = 0; i < order.size(); ++i) out[{order[i].level, order[i].x, order[i].y}] = i;
  return out;
}

const ImageInfo kGeometries[] = {
    makeInfo(1, 1, 64),      makeInfo(1, 300, 64),    makeInfo(300, 1, 64),
    makeInfo(1000, 999, 64), makeInfo(257, 513, 128), makeInfo(4097, 4095, 256),
    makeInfo(5000, 300, 64), makeInfo(512, 512, 64),
};

TEST(TileOrder, EveryOrderListsEveryTileOfEveryLevelExactlyOnce) {
  for (const ImageInfo& info : kGeometries) {
    uint64_t total = 0;
    for (uint32_t l = 0; l < info.level_count; ++l)
      total += uint64_t(info.tilesX(l)) * info.tilesY(l);
    for (TileOrder order : {TileOrder::kHilbert, TileOrder::kQuadtree, TileOrder::kRowMajor}) {
      std::vector<TileId> tiles = tileOrder(info, 7, order);
      ASSERT_EQ(tiles.size(), total) << info.width_px << "x" << info.height_px;
      std::set<Key> seen;
      for (const TileId& tile : tiles) {
        ASSERT_EQ(tile.image, 7u);
        ASSERT_LT(tile.level, info.level_count);
        ASSERT_LT(tile.x, info.tilesX(tile.level));
        ASSERT_LT(tile.y, info.tilesY(tile.level));
        ASSERT_TRUE(seen.insert({tile.level, tile.x, tile.y}).second)
            << "duplicate tile (" << tile.level << "," << tile.x << "," << tile.y << ")";
      }
    }
  }
}

TEST(TileOrder, HilbertAndRowMajorPutCoarserLevelsFirst) {
  for (const ImageInfo& info : kGeometries) {
    for (TileOrder order : {TileOrder::kHilbert, TileOrder::kRowMajor}) {
      std::vector<TileId> tiles = tileOrder(info, 0, order);
      EXPECT_EQ(tiles.front().level, info.level_count - 1);
      for (size_t i = 1; i < tiles.size(); ++i)
        ASSERT_LE(tiles[i].level, tiles[i - 1].level) << "position " << i;
    }
  }
}

TEST(TileOrder, RowMajorGoesRowByRowWithinALevel) {
  ImageInfo info = makeInfo(1000, 999, 64);
  std::vector<TileId> tiles = tileOrder(info, 0, TileOrder::kRowMajor);
  for (size_t i = 1; i < tiles.size(); ++i) {
    if (tiles[i].level != tiles[i - 1].level) continue;
    bool next_in_row = tiles[i].y == tiles[i - 1].y && tiles[i].x == tiles[i - 1].x + 1;
    bool next_row = tiles[i].y == tiles[i - 1].y + 1 && tiles[i].x == 0 &&
                    tiles[i - 1].x == info.tilesX(tiles[i].level) - 1;
    ASSERT_TRUE(next_in_row || next_row) << i;
  }
}

TEST(TileOrder, HilbertStepsToANeighbourWithinAPowerOfTwoGrid) {
  // 512 px with 64 px tiles: levels of 8x8, 4x4, 2x2 and 1x1 tiles.
  ImageInfo info = makeInfo(512, 512, 64);
  std::vector<TileId> tiles = tileOrder(info, 0, TileOrder::kHilbert);
  for (size_t i = 1; i < tiles.size(); ++i) {
    if (tiles[i].level != tiles[i - 1].level) continue;
    int64_t step = std::abs(int64_t(tiles[i].x) - tiles[i - 1].x) +
                   std::abs(int64_t(tiles[i].y) - tiles[i - 1].y);
    ASSERT_EQ(step, 1) << "position " << i;
  }
}

TEST(TileOrder, QuadtreeListsEachParentBeforeItsChildren) {
  for (const ImageInfo& info : kGeometries) {
    std::vector<TileId> tiles = tileOrder(info, 0, TileOrder::kQuadtree);
    std::map<Key, size_t> at = positions(tiles);
    for (const TileId& tile : tiles) {
      if (tile.level + 1 == info.level_count) continue;
      auto parent = at.find({tile.level + 1, tile.x / 2, tile.y / 2});
      ASSERT_NE(parent, at.end());
      ASSERT_LT(parent->second, at[Key(tile.level, tile.x, tile.y)]);
    }
  }
}

TEST(TileOrder, QuadtreeSubtreesAreContiguous) {
  for (const ImageInfo& info : kGeometries) {
    std::vector<TileId> tiles = tileOrder(info, 0, TileOrder::kQuadtree);
    auto descends = [](const TileId& tile, const TileId& root) {
      if (tile.level >= root.level) return false;
      uint32_t shift = root.level - tile.level;
      return (tile.x >> shift) == root.x && (tile.y >> shift) == root.y;
    };
    for (size_t i = 0; i < tiles.size(); ++i) {
      size_t descendants = 0;
      for (const TileId& tile : tiles) descendants += descends(tile, tiles[i]);
      for (size_t k = 1; k <= descendants; ++k)
        ASSERT_TRUE(descends(tiles[i + k], tiles[i]))
            << info.width_px << "x" << info.height_px << ": subtree of position " << i
            << " broken at " << i + k;
    }
  }
}

}  // namespace
}  // namespace tessera::detail
