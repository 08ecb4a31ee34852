// Viewer-shift eviction against LRU in the scenario of Luo & Duan, Fig. 7 and 8: rows A..G of
// tiles are cached, the clip centre sits on row C and then moves down to row D. LRU throws
// away row G (cached ahead of the viewer but not shown yet); viewer-shift throws away row A
// (left behind by the motion).
#include <tessera/cache.h>

#include <algorithm>
#include <memory>
#include <set>

#include <gtest/gtest.h>

namespace tessera {
namespace {

constexpr uint32_t kTileSizePx = 256;
constexpr uint32_t kColumns = 4;
constexpr uint32_t kRows = 7;  // A..G
enum Row : uint32_t { A, B, C, D, E, F, G, H };

TileId at(uint32_t column, uint32_t row) {
  return {0, 0, column, row};
}

/// The tile-row's centre in level-0 pixels.
double rowCentre(uint32_t row) {
  return (row + 0.5) * kTileSizePx;
}

std::shared_ptr<const DecodedTile> makeTile(const TileId& id) {
  auto tile = std::make_shared<DecodedTile>();
  tile->id = id;
  tile->texels = Image(8, 8, 4);
  tile->texels.texels[0] = uint8_t(id.x * 16 + id.y);
  return tile;
}

size_t tileBytes() {
  return makeTile(at(0, 0))->bytes();
}

/// Motion from row `from` to row `to`, the viewer in the middle column.
ViewerMotion motionBetweenRows(uint32_t from, uint32_t to) {
  ViewerMotion motion;
  motion.centre_x = kColumns * kTileSizePx / 2.0;
  motion.centre_y = rowCentre(to);
  motion.motion_x = 0;
  motion.motion_y = rowCentre(to) - rowCentre(from);
  motion.tile_size_px = kTileSizePx;
  return motion;
}

/// Fig. 7: rows A..G loaded in order; while the centre is on row C the view shows rows A..E
/// every frame (F and G were loaded ahead and not shown since). Then the centre moves to D
/// and the view shows B..F.
void replayFigureSeven(TileCache& cache) {
  for (uint32_t row = A; row <= G; ++row)
    for (uint32_t column = 0; column < kColumns; ++column)
      ASSERT_TRUE(cache.insert(makeTile(at(column, row))));
  cache.setViewerMotion(motionBetweenRows(C, C));
  for (int frame = 0; frame < 3; ++frame)
    for (uint32_t row = A; row <= E; ++row)
      for (uint32_t column = 0; column < kColumns; ++column)
        ASSERT_TRUE(cache.find(at(column, row)));
  cache.setViewerMotion(motionBetweenRows(C, D));
  for (uint32_t row = B; row <= F; ++row)
    for (uint32_t column = 0; column < kColumns; ++column) ASSERT_TRUE(cache.find(at(column, row)));
}

std::set<uint32_t> rowsEvictedByLoadingRowH(TileCache& cache) {
  // Row H comes into the clip region: room for one of its tiles.
  EXPECT_TRUE(cache.insert(makeTile(at(0, H))));
  std::set<uint32_t> rows;
  for (uint32_t row = A; row <= G; ++row)
    for (uint32_t column = 0; column < kColumns; ++column)
      if (!cache.contains(at(column, row))) rows.insert(row);
  return rows;
}

TEST(ViewerShiftEviction, FigureEightEvictsRowABehindTheMotionFirst) {
  TileCache cache(kColumns * kRows * tileBytes(), makeViewerShiftPolicy());
  replayFigureSeven(cache);
  EXPECT_EQ(rowsEvictedByLoadingRowH(cache), (std::set<uint32_t>{A}));
  EXPECT_EQ(cache.stats().evictions, 1u);
}

TEST(ViewerShiftEviction, LruInTheSameScenarioEvictsRowGAheadOfTheViewer) {
  TileCache cache(kColumns * kRows * tileBytes(), makeLruPolicy());
  replayFigureSeven(cache);
  EXPECT_EQ(rowsEvictedByLoadingRowH(cache), (std::set<uint32_t>{G}));
  EXPECT_EQ(cache.stats().evictions, 1u);
}

TEST(ViewerShiftEviction, OrdersAllCandidatesFromFarthestBehindToFarthestAhead) {
  auto policy = makeViewerShiftPolicy();
  EXPECT_STREQ(policy->name(), "viewer-shift");
  for (uint32_t row = A; row <= G; ++row)
    for (uint32_t column = 0; column < kColumns; ++column) policy->onInsert(at(column, row));
  policy->onViewerMotion(motionBetweenRows(C, D));
  std::vector<TileId> victims;
  policy->victims(kRows * kColumns, victims);
  ASSERT_EQ(victims.size(), kRows * kColumns);
  for (size_t i = 1; i < victims.size(); ++i)
    EXPECT_LE(victims[i - 1].y, victims[i].y) << "victim " << i;
  EXPECT_EQ(victims.front().y, uint32_t(A));
  EXPECT_EQ(victims.back().y, uint32_t(G));
}

TEST(ViewerShiftEviction, MovingUpReversesTheOrder) {
  auto policy = makeViewerShiftPolicy();
  for (uint32_t row = A; row <= G; ++row)
    for (uint32_t column = 0; column < kColumns; ++column) policy->onInsert(at(column, row));
  policy->onViewerMotion(motionBetweenRows(E, D));
  std::vector<TileId> victims;
  policy->victims(kColumns, victims);
  ASSERT_EQ(victims.size(), kColumns);
  for (const TileId& id : victims) EXPECT_EQ(id.y, uint32_t(G));
}

TEST(ViewerShiftEviction, SidewaysMotionEvictsTheColumnLeftBehind) {
  auto policy = makeViewerShiftPolicy();
  for (uint32_t row = A; row <= G; ++row)
    for (uint32_t column = 0; column < kColumns; ++column) policy->onInsert(at(column, row));
  ViewerMotion motion;
  motion.centre_x = 2.5 * kTileSizePx;
  motion.centre_y = rowCentre(D);
  motion.motion_x = -double(kTileSizePx);  // moving left: the rightmost column is behind
  motion.tile_size_px = kTileSizePx;
  policy->onViewerMotion(motion);
  std::vector<TileId> victims;
  policy->victims(kRows, victims);
  ASSERT_EQ(victims.size(), kRows);
  for (const TileId& id : victims) EXPECT_EQ(id.x, kColumns - 1);
}

TEST(ViewerShiftEviction, TilesInsideKeepRegionsGoLast) {
  auto policy = makeViewerShiftPolicy();
  for (uint32_t row = A; row <= G; ++row)
    for (uint32_t column = 0; column < kColumns; ++column) policy->onInsert(at(column, row));
  ViewerMotion motion = motionBetweenRows(C, D);
  // Keep rows A and B (say the expanded region reaches there): row C is now the first to go.
  motion.keep_regions.push_back({0, 0, 0, A, kColumns, C});
  policy->onViewerMotion(motion);
  std::vector<TileId> victims;
  policy->victims(kRows * kColumns, victims);
  ASSERT_EQ(victims.size(), kRows * kColumns);
  const size_t unkept = (kRows - 2) * kColumns;
  for (size_t i = 0; i < unkept; ++i) EXPECT_GE(victims[i].y, uint32_t(C)) << i;
  for (size_t i = unkept; i < victims.size(); ++i) EXPECT_LT(victims[i].y, uint32_t(C)) << i;
  EXPECT_EQ(victims[0].y, uint32_t(C));
  // Among kept tiles the farthest from the viewer (row A, 3 rows from D) goes first.
  for (size_t i = unkept; i < unkept + kColumns; ++i) EXPECT_EQ(victims[i].y, uint32_t(A)) << i;
}

TEST(ViewerShiftEviction, KeepRegionsMatchOnlyTheirImageAndLevel) {
  auto policy = makeViewerShiftPolicy();
  const TileId near_level1{0, 1, 0, 0}, other_image{1, 0, 0, 0}, kept{0, 0, 0, 0};
  for (const TileId& id : {near_level1, other_image, kept}) policy->onInsert(id);
  ViewerMotion motion;
  motion.motion_x = 1;
  motion.tile_size_px = kTileSizePx;
  motion.keep_regions.push_back({0, 0, 0, 0, 1, 1});
  policy->onViewerMotion(motion);
  std::vector<TileId> victims;
  policy->victims(3, victims);
  ASSERT_EQ(victims.size(), 3u);
  EXPECT_EQ(victims.back(), kept);
}

TEST(ViewerShiftEviction, StillViewerKeepsTheLastDirection) {
  auto policy = makeViewerShiftPolicy();
  for (uint32_t row = A; row <= G; ++row) policy->onInsert(at(0, row));
  policy->onViewerMotion(motionBetweenRows(C, D));
  policy->onViewerMotion(motionBetweenRows(D, D));  // no motion this frame
  std::vector<TileId> victims;
  policy->victims(1, victims);
  ASSERT_EQ(victims.size(), 1u);
  EXPECT_EQ(victims[0].y, uint32_t(A));
}

TEST(ViewerShiftEviction, WithoutAnyMotionTheFarthestTileGoesFirst) {
  auto policy = makeViewerShiftPolicy();
  for (uint32_t row = A; row <= G; ++row) policy->onInsert(at(0, row));
  ViewerMotion motion;
  motion.centre_x = 0.5 * kTileSizePx;
  motion.centre_y = rowCentre(B);
  motion.tile_size_px = kTileSizePx;
  policy->onViewerMotion(motion);
  std::vector<TileId> victims;
  policy->victims(2, victims);
  EXPECT_EQ(victims, (std::vector<TileId>{at(0, G), at(0, F)}));
}

TEST(ViewerShiftEviction, ErasedTilesAreNoLongerCandidates) {
  auto policy = makeViewerShiftPolicy();
  for (uint32_t row = A; row <= G; ++row) policy->onInsert(at(0, row));
  policy->onViewerMotion(motionBetweenRows(C, D));
  policy->onErase(at(0, A));
  std::vector<TileId> victims;
  policy->victims(10, victims);
  EXPECT_EQ(victims.size(), kRows - 1);
  EXPECT_EQ(std::count(victims.begin(), victims.end(), at(0, A)), 0);
  EXPECT_EQ(victims.front(), at(0, B));
}

TEST(ViewerShiftEviction, CoarserLevelTilesAreProjectedAtTheirLevelZeroPosition) {
  auto policy = makeViewerShiftPolicy();
  // Level 2 tile (0, 0) spans level-0 rows 0..3 (centre at 2 tiles); level 0 tile (0, 6) lies
  // below the viewer at row D.
  const TileId coarse{0, 2, 0, 0}, below{0, 0, 0, 6};
  policy->onInsert(below);
  policy->onInsert(coarse);
  policy->onViewerMotion(motionBetweenRows(C, D));
  std::vector<TileId> victims;
  policy->victims(2, victims);
  EXPECT_EQ(victims, (std::vector<TileId>{coarse, below}));
}

}  // namespace
}  // namespace tessera
