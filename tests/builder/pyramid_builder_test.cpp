// The streaming pyramid: fed rows in bands of any height, it announces every tile row of every
// level exactly once, in order, each time with the rows it needs, and the tiles cut from them
// equal the reference pyramid, also when the sink cuts them only when the builder says it must.
#include "builder/pyramid_builder.h"

#include <cstring>
#include <deque>
#include <map>

#include <gtest/gtest.h>

#include "support/reference_pyramid.h"

namespace tessera::detail {
namespace {

class CollectingSink final : public TileSink {
 public:
  CollectingSink(const ImageInfo& info, const test::ReferencePyramid& reference)
      : info_(info), reference_(reference) {}

  Result<void> tileRowReady(uint32_t level, uint32_t tile_row, const LevelRows& rows) override {
    uint32_t& next = next_row_[level];
    EXPECT_EQ(tile_row, next) << "level " << level << " tile rows out of order";
    next = tile_row + 1;
    EXPECT_EQ(rows.width_px, info_.levelWidthPx(level));
    EXPECT_EQ(rows.height_px, info_.levelHeightPx(level));
    if (cut_later)
      uncut_[level].push_back({tile_row, &rows});
    else
      cutRow(level, tile_row, rows);
    if (fail_at_level == int(level)) return fail(ErrorCode::kIo, "sink full");
    return {};
  }

  // As late as the builder allows: a row overwritten too early shows as a tile that differs
  // from the reference, one never awaited as a tile never cut.
  bool cutsLater() const override { return cut_later; }
  void awaitCut(uint32_t level, uint32_t tile_row) override {
    EXPECT_LT(tile_row, next_row_[level]) << "level " << level << " awaits an unannounced row";
    std::deque<std::pair<uint32_t, const LevelRows*>>& uncut = uncut_[level];
    while (!uncut.empty() && uncut.front().first <= tile_row) {
      cutRow(level, uncut.front().first, *uncut.front().second);
      uncut.pop_front();
    }
  }

  uint32_t rowsAnnounced(uint32_t level) { return next_row_[level]; }
  int tiles = 0;
  int mismatches = 0;
  int fail_at_level = -1;
  bool cut_later = false;

 private:
  void cutRow(uint32_t level, uint32_t tile_row, const LevelRows& rows) {
    std::vector<uint8_t> tile(info_.storedTileBytes());
    for (uint32_t x = 0; x < info_.tilesX(level); ++x) {
      cutTile(rows, info_.tile_size_px, info_.border_px, x, tile_row, tile.data());
      test::ReferenceTile expected =
          reference_.tile(level, x, tile_row, info_.tile_size_px, info_.border_px);
      ++tiles;
      if (tile != expected.texels.texels) {
        ++mismatches;
        if (mismatches == 1)
          ADD_FAILURE() << "tile (" << level << "," << x << "," << tile_row << ") differs";
      }
    }
  }

  std::map<uint32_t, std::deque<std::pair<uint32_t, const LevelRows*>>> uncut_;
  const ImageInfo& info_;
  const test::ReferencePyramid& reference_;
  std::map<uint32_t, uint32_t> next_row_;
};

ImageInfo makeInfo(const Image& image, uint32_t tile, uint32_t border) {
  ImageInfo info;
  info.width_px = image.width_px;
  info.height_px = image.height_px;
  info.channels = image.channels;
  info.tile_size_px = tile;
  info.border_px = border;
  info.level_count = levelCountFor(image.width_px, image.height_px, tile);
  return info;
}

// Every level announced all its tile rows and every tile was cut once, equal to the reference.
void expectEveryTileOnce(const ImageInfo& info, CollectingSink& sink) {
  int expected_tiles = 0;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    EXPECT_EQ(sink.rowsAnnounced(level), info.tilesY(level)) << "level " << level;
    expected_tiles += info.tilesX(level) * info.tilesY(level);
  }
  EXPECT_EQ(sink.tiles, expected_tiles);
  EXPECT_EQ(sink.mismatches, 0);
}

struct Case {
  uint32_t width, height, channels, tile, border, band_rows;
};

void PrintTo(const Case& c, std::ostream* out) {
  *out << c.width << "x" << c.height << " c" << c.channels << " t" << c.tile << " b" << c.border
       << " rows" << c.band_rows;
}

class PyramidBuilderTest : public testing::TestWithParam<Case> {};

// Rows through addRows, in bands of the case's height.
void feedCopies(const Case& c, const Image& image, PyramidBuilder& pyramid) {
  for (uint32_t y = 0; y < c.height; y += c.band_rows) {
    uint32_t rows = std::min(c.band_rows, c.height - y);
    ASSERT_TRUE(pyramid.addRows(image.row(y), rows));
    EXPECT_EQ(pyramid.rowsReceived(), y + rows);
  }
}

// Rows through rowsToFill/commitRows (the builder's path: the reader decodes into the band),
// each span filled and committed, sometimes only in part.
void feedInPlace(const Case& c, const Image& image, PyramidBuilder& pyramid) {
  const size_t row_bytes = size_t(c.width) * c.channels;
  uint32_t y = 0, step = 0;
  while (y < c.height) {
    std::span<uint8_t> slots = pyramid.rowsToFill(c.band_rows);
    ASSERT_FALSE(slots.empty()) << "row " << y;
    ASSERT_EQ(slots.size() % row_bytes, 0u);
    uint32_t rows = uint32_t(slots.size() / row_bytes);
    ASSERT_LE(rows, c.band_rows);
    if (++step % 3 == 0) rows = (rows + 1) / 2;  // a reader may fill less than offered
    std::memcpy(slots.data(), image.row(y), rows * row_bytes);
    ASSERT_TRUE(pyramid.commitRows(rows));
    y += rows;
    ASSERT_EQ(pyramid.rowsReceived(), y);
  }
  EXPECT_TRUE(pyramid.rowsToFill(c.band_rows).empty());
}

void buildAndCompare(const Case& c, void (*feed)(const Case&, const Image&, PyramidBuilder&),
                     bool cut_later = false) {
  Image image = test::makePatternImage(c.width, c.height, c.channels, c.width ^ c.height);
  test::ReferencePyramid reference(image);
  ImageInfo info = makeInfo(image, c.tile, c.border);
  CollectingSink sink(info, reference);
  sink.cut_later = cut_later;
  {
    PyramidBuilder pyramid(info, sink);
    feed(c, image, pyramid);
    ASSERT_TRUE(pyramid.finish());
  }  // the builder awaits the last tile rows' cuts as it goes
  expectEveryTileOnce(info, sink);
}

TEST_P(PyramidBuilderTest, EmitsEveryTileOnceAndEqualToTheReference) {
  buildAndCompare(GetParam(), feedCopies);
}

// In place, the tiles still equal the reference: no span ever covers a row that a tile row's
// announcement or a 2x2 pair still needed.
TEST_P(PyramidBuilderTest, InPlaceRowsGiveTheSameTiles) {
  buildAndCompare(GetParam(), feedInPlace);
}

// A sink that cuts later (the builder's encoders) gets every tile intact: the builder waits for
// a tile row's cuts before it overwrites its rows, and for the last ones before it goes.
TEST_P(PyramidBuilderTest, TilesCutLaterEqualTheReference) {
  buildAndCompare(GetParam(), feedCopies, /*cut_later=*/true);
  buildAndCompare(GetParam(), feedInPlace, /*cut_later=*/true);
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, PyramidBuilderTest,
    testing::Values(Case{1, 1, 1, 64, 0, 1}, Case{1, 300, 2, 64, 1, 1}, Case{300, 1, 3, 64, 4, 1},
                    Case{257, 513, 4, 64, 4, 7}, Case{257, 513, 1, 128, 16, 64},
                    Case{200, 130, 2, 64, 0, 130}, Case{129, 129, 3, 64, 1, 3},
                    Case{640, 400, 4, 64, 2, 256}, Case{1000, 999, 3, 256, 1, 100},
                    Case{700, 600, 3, 64, 0, 64}, Case{333, 700, 3, 64, 3, 1000}),
    [](const testing::TestParamInfo<Case>& param_info) {
      const Case& c = param_info.param;
      return std::to_string(c.width) + "x" + std::to_string(c.height) + "c" +
             std::to_string(c.channels) + "t" + std::to_string(c.tile) + "b" +
             std::to_string(c.border) + "rows" + std::to_string(c.band_rows);
    });

TEST(PyramidBuilder, FinishBeforeAllRowsFailsNamingTheLevel) {
  Image image = test::makePatternImage(100, 100, 1, 1);
  test::ReferencePyramid reference(image);
  ImageInfo info = makeInfo(image, 64, 0);
  CollectingSink sink(info, reference);
  PyramidBuilder pyramid(info, sink);
  ASSERT_TRUE(pyramid.addRows(image.row(0), 99));
  auto finished = pyramid.finish();
  ASSERT_FALSE(finished);
  EXPECT_NE(finished.error().message.find("level 0"), std::string::npos)
      << finished.error().message;
}

TEST(PyramidBuilder, ASinkFailureStopsAddRows) {
  Image image = test::makePatternImage(100, 100, 1, 1);
  test::ReferencePyramid reference(image);
  ImageInfo info = makeInfo(image, 64, 0);
  CollectingSink sink(info, reference);
  sink.fail_at_level = 0;
  PyramidBuilder pyramid(info, sink);
  auto added = pyramid.addRows(image.row(0), 100);
  ASSERT_FALSE(added);
  EXPECT_EQ(added.error().message, "sink full");
}

}  // namespace
}  // namespace tessera::detail
