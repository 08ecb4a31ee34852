// The residency manager: which tiles a view wants and in what order (Backes et al., sections
// 5-6; Luo & Duan, section 3.3). Pure policy, tested without an archive: an ImageInfo is enough.
#include "stream/residency.h"

#include <algorithm>
#include <map>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

ImageInfo imageOf(uint32_t width_px, uint32_t height_px, uint32_t tile_size_px) {
  ImageInfo info;
  info.width_px = width_px;
  info.height_px = height_px;
  info.channels = 3;
  info.tile_size_px = tile_size_px;
  info.level_count = levelCountFor(width_px, height_px, tile_size_px);
  return info;
}

View orthoView(double centre_x, double centre_y, double tpp, uint32_t w, uint32_t h) {
  View view;
  view.ortho.centre_x = centre_x;
  view.ortho.centre_y = centre_y;
  view.ortho.texels_per_pixel = tpp;
  view.ortho.viewport_w = w;
  view.ortho.viewport_h = h;
  return view;
}

using Key = std::tuple<uint32_t, uint32_t, uint32_t>;  // level, x, y
Key keyOf(const TileId& id) {
  return {id.level, id.x, id.y};
}

std::set<Key> prefetchOf(const ResidencyPlan& plan) {
  std::set<Key> out;
  for (const TileRequest& r : plan.wanted)
    if (r.prefetch) out.insert(keyOf(r.id));
  return out;
}

TileRect clipAt(const ResidencyPlan& plan, uint32_t level) {
  for (const auto& region : plan.clip_regions)
    if (region.level == level) return region.region;
  ADD_FAILURE() << "no clip region at level " << level;
  return {};
}

void expectAllInsideGrid(const ResidencyPlan& plan, const ImageInfo& info) {
  for (const TileRequest& r : plan.wanted) {
    ASSERT_LT(r.id.level, info.level_count);
    EXPECT_LT(r.id.x, info.tilesX(r.id.level)) << r.id.level << "," << r.id.x << "," << r.id.y;
    EXPECT_LT(r.id.y, info.tilesY(r.id.level)) << r.id.level << "," << r.id.x << "," << r.id.y;
  }
  for (const TileId& id : plan.visible) {
    EXPECT_LT(id.x, info.tilesX(id.level));
    EXPECT_LT(id.y, info.tilesY(id.level));
  }
}

TEST(Residency, OddImageSizeWantsTheHandWorkedVisibleTilesAndClipsRegionsToTheGrid) {
  // 1000x777 at 128 px: level 0 is 8x7 tiles, level 1 (500x389) 4x4, level 2 2x2, level 3 1x1.
  ImageInfo info = imageOf(1000, 777, 128);
  ASSERT_EQ(info.level_count, 4u);
  ResidencyManager residency(info, 0, {});
  const ResidencyPlan& plan = residency.plan(orthoView(500, 388, 1, 640, 480));
  EXPECT_EQ(plan.desired_level, 0u);
  expectAllInsideGrid(plan, info);
  // Footprint [180, 820] x [148, 628] px: columns 1..6, rows 1..4.
  std::set<Key> visible;
  for (const TileId& id : plan.visible) visible.insert(keyOf(id));
  std::set<Key> expected;
  for (uint32_t y = 1; y <= 4; ++y)
    for (uint32_t x = 1; x <= 6; ++x) expected.insert({0, x, y});
  EXPECT_EQ(visible, expected);
  // n = ceil(640 / 128) * 2 = 10 around tile (3, 3): [-2, 8)^2, clipped to the 8x7 grid.
  EXPECT_EQ(clipAt(plan, 0), (TileRect{0, 0, 8, 7}));
  EXPECT_EQ(clipAt(plan, 1), (TileRect{0, 0, 4, 4}));
  EXPECT_EQ(clipAt(plan, 3), (TileRect{0, 0, 1, 1}));
}

TEST(Residency, ClipRegionAwayFromTheEdgesIsNTilesSquare) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  const ResidencyPlan& plan = residency.plan(orthoView(8300, 5000, 1, 1920, 1080));
  // n = 16 around (floor(8300/256), floor(5000/256)) = (32, 19).
  EXPECT_EQ(clipAt(plan, 0), (TileRect{24, 11, 40, 27}));
  // One level up the same block of the image: [12, 20) x [5, 14).
  EXPECT_EQ(clipAt(plan, 1), (TileRect{12, 5, 20, 14}));
}

TEST(Residency, ViewPartlyOutsideTheTextureWantsNoTileOutsideTheGrid) {
  ImageInfo info = imageOf(1000, 777, 128);
  for (auto [cx, cy] : {std::pair{-100.0, -100.0}, std::pair{1100.0, 900.0},
                        std::pair{-300.0, 400.0}, std::pair{500.0, 1000.0}}) {
    ResidencyManager residency(info, 0, {});
    const ResidencyPlan& plan = residency.plan(orthoView(cx, cy, 1, 640, 480));
    SCOPED_TRACE(testing::Message() << "centre " << cx << "," << cy);
    expectAllInsideGrid(plan, info);
    EXPECT_FALSE(plan.visible.empty());
  }
  ResidencyManager residency(info, 0, {});
  const ResidencyPlan& plan = residency.plan(orthoView(-100, -100, 1, 640, 480));
  // Footprint [-420, 220] x [-340, 140]: in the grid only columns 0..1 and rows 0..1.
  std::set<Key> visible;
  for (const TileId& id : plan.visible) visible.insert(keyOf(id));
  EXPECT_EQ(visible, (std::set<Key>{{0, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0, 1, 1}}));
}

TEST(Residency, ViewWhollyOutsideTheTextureWantsOnlyTheCoarsestLevel) {
  ImageInfo info = imageOf(1000, 777, 128);
  for (auto [cx, cy] : {std::pair{-5000.0, -5000.0}, std::pair{1e6, 1e6}, std::pair{500.0, -3000.0},
                        std::pair{1e12, -1e12}}) {
    ResidencyManager residency(info, 0, {});
    const ResidencyPlan& plan = residency.plan(orthoView(cx, cy, 1, 640, 480));
    SCOPED_TRACE(testing::Message() << "centre " << cx << "," << cy);
    expectAllInsideGrid(plan, info);
    EXPECT_TRUE(plan.visible.empty());
    ASSERT_FALSE(plan.wanted.empty());
    for (const TileRequest& r : plan.wanted) EXPECT_EQ(r.id.level, info.level_count - 1);
  }
}

TEST(Residency, ExtremeZoomInWantsTheOneLevelZeroTileUnderTheView) {
  // 1/64 texel per pixel: 1280x720 screen pixels show 20x11.25 texels around (448, 448).
  ImageInfo info = imageOf(1000, 777, 128);
  ResidencyManager residency(info, 0, {});
  const ResidencyPlan& plan = residency.plan(orthoView(448, 448, 1.0 / 64, 1280, 720));
  EXPECT_EQ(plan.desired_level, 0u);
  ASSERT_EQ(plan.visible.size(), 1u);
  EXPECT_EQ(keyOf(plan.visible[0]), (Key{0, 3, 3}));
  expectAllInsideGrid(plan, info);
}

TEST(Residency, ExtremeZoomOutWantsOnlyCoarseLevels) {
  // 16384^2 at 256 px: 7 levels. The whole image in 8 screen pixels (2048 texels per pixel).
  ImageInfo info = imageOf(16384, 16384, 256);
  ASSERT_EQ(info.level_count, 7u);
  {
    ResidencyManager residency(info, 0, {});
    const ResidencyPlan& plan = residency.plan(orthoView(8192, 8192, 2048, 1280, 720));
    EXPECT_EQ(plan.desired_level, 6u);
    for (const TileRequest& r : plan.wanted) EXPECT_EQ(r.id.level, 6u);
  }
  {
    // 32 texels per pixel: level 5 and the coarsest only.
    ResidencyManager residency(info, 0, {});
    const ResidencyPlan& plan = residency.plan(orthoView(8192, 8192, 32, 1280, 720));
    EXPECT_EQ(plan.desired_level, 5u);
    std::set<uint32_t> levels;
    for (const TileRequest& r : plan.wanted) levels.insert(r.id.level);
    EXPECT_EQ(levels, (std::set<uint32_t>{5, 6}));
    expectAllInsideGrid(plan, info);
  }
}

TEST(Residency, CentreMovesInsideTheEffectiveRegionKeepTheClipRegion) {
  // n = 16 (FHD at 256 px): the effective region is floor(n/2) = 8 tiles wide, so the clip
  // centre (tile 16) stays while the view centre is within 4 tiles of it.
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.max_centre_step_tiles = 100;
  ResidencyManager residency(info, 0, options);
  const double t = 256;
  TileRect initial = clipAt(residency.plan(orthoView(16.5 * t, 16.5 * t, 1, 1920, 1080)), 0);
  EXPECT_EQ(initial, (TileRect{8, 8, 24, 24}));
  for (double fx : {17.0, 18.5, 19.9, 20.0, 16.1, 13.0, 12.0})
    EXPECT_EQ(clipAt(residency.plan(orthoView(fx * t, 16.5 * t, 1, 1920, 1080)), 0), initial)
        << "centre at tile " << fx;
  for (double fy : {19.9, 12.5})
    EXPECT_EQ(clipAt(residency.plan(orthoView(16.5 * t, fy * t, 1, 1920, 1080)), 0), initial)
        << "centre at row " << fy;
}

TEST(Residency, CentreLeavingTheEffectiveRegionRecentresTheClipRegion) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.max_centre_step_tiles = 100;
  ResidencyManager residency(info, 0, options);
  const double t = 256;
  residency.plan(orthoView(16.5 * t, 16.5 * t, 1, 1920, 1080));
  // 4.5 tiles right of the centre tile: recentre on tile 20.
  EXPECT_EQ(clipAt(residency.plan(orthoView(20.5 * t, 16.5 * t, 1, 1920, 1080)), 0),
            (TileRect{12, 8, 28, 24}));
  // Hysteresis: stepping back a little does not move it back.
  EXPECT_EQ(clipAt(residency.plan(orthoView(19.9 * t, 16.5 * t, 1, 1920, 1080)), 0),
            (TileRect{12, 8, 28, 24}));
  // Up and to the left beyond the effective region: both axes recentre.
  EXPECT_EQ(clipAt(residency.plan(orthoView(14.5 * t, 10.2 * t, 1, 1920, 1080)), 0),
            (TileRect{6, 2, 22, 18}));
}

TEST(Residency, MaxCentreStepLimitsHowFarTheClipRegionMovesPerFrame) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.max_centre_step_tiles = 2;
  ResidencyManager residency(info, 0, options);
  const double t = 256;
  EXPECT_EQ(clipAt(residency.plan(orthoView(16.5 * t, 16.5 * t, 1, 1920, 1080)), 0).x0, 8);
  // A jump of 10 tiles right: the centre approaches 2 tiles a frame (18, 20, 22, 24) and stops
  // once the view centre (26.5) is inside the effective region (within 4 tiles).
  std::vector<int64_t> x0s;
  for (int frame = 0; frame < 6; ++frame)
    x0s.push_back(clipAt(residency.plan(orthoView(26.5 * t, 16.5 * t, 1, 1920, 1080)), 0).x0);
  EXPECT_EQ(x0s, (std::vector<int64_t>{10, 12, 14, 16, 16, 16}));
}

TEST(Residency, AHeldViewReplansUntilItsPlanSettlesThenReusesIt) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.max_centre_step_tiles = 2;
  ResidencyManager residency(info, 0, options);
  const double t = 256;
  residency.plan(orthoView(16.5 * t, 16.5 * t, 1, 1920, 1080));
  // 10 tiles right (a flight, not a jump): the clip centre steps 2 tiles a plan, so holding
  // the view still changes the plan for four more frames.
  const View held = orthoView(26.5 * t, 16.5 * t, 1, 1920, 1080);
  std::vector<int64_t> x0s;
  std::vector<uint64_t> computed;
  size_t prefetch_first = 0, prefetch_after = 0;
  for (int frame = 0; frame < 8; ++frame) {
    const ResidencyPlan& plan = residency.plan(held);
    x0s.push_back(clipAt(plan, 0).x0);
    computed.push_back(residency.plansComputed());
    (frame == 0 ? prefetch_first : prefetch_after) += prefetchOf(plan).size();
  }
  EXPECT_EQ(x0s, (std::vector<int64_t>{10, 12, 14, 16, 16, 16, 16, 16}));
  // Computed while the centre stepped, once more to see it stay, then reused.
  EXPECT_EQ(computed, (std::vector<uint64_t>{2, 3, 4, 5, 6, 6, 6, 6}));
  // The move's prefetch (the column it crossed into) went with the first plan: the held view
  // has no motion, and its reused plan prefetches nothing.
  EXPECT_GT(prefetch_first, 0u);
  EXPECT_EQ(prefetch_after, 0u);
  EXPECT_EQ(residency.plan(held).motion.motion_x, 0);
  // Any change of the view plans again: a pixel's move, a zoom, a rotation.
  View moved = held;
  moved.ortho.centre_x += 1;
  residency.plan(moved);
  EXPECT_EQ(residency.plansComputed(), 7u);
  View rotated = moved;
  rotated.ortho.rotation_rad = 0.1;
  residency.plan(rotated);
  EXPECT_EQ(residency.plansComputed(), 8u);
}

TEST(Residency, AReusedPlanWantsWhatAFreshPlanOfTheSameViewWants) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, ResidencyOptions{});
  const View view = orthoView(5000, 7000, 1.5, 1280, 720);
  residency.plan(orthoView(4000, 7000, 1.5, 1280, 720));
  for (int frame = 0; frame < 4; ++frame) residency.plan(view);
  const uint64_t computed = residency.plansComputed();
  const std::vector<TileRequest> reused = residency.plan(view).wanted;
  ASSERT_EQ(residency.plansComputed(), computed) << "the held view was planned again";
  // A manager that saw the view held for one frame computes its plan afresh.
  ResidencyManager fresh(info, 0, ResidencyOptions{});
  fresh.plan(orthoView(4000, 7000, 1.5, 1280, 720));
  fresh.plan(view);
  const std::vector<TileRequest> expected = fresh.plan(view).wanted;
  ASSERT_EQ(reused.size(), expected.size());
  for (size_t i = 0; i < reused.size(); ++i) {
    EXPECT_EQ(keyOf(reused[i].id), keyOf(expected[i].id)) << i;
    EXPECT_EQ(reused[i].priority, expected[i].priority) << i;
  }
}

TEST(Residency, MaxCentreStepStillWantsWhatTheViewShows) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.max_centre_step_tiles = 1;
  ResidencyManager residency(info, 0, options);
  residency.plan(orthoView(2000, 2000, 1, 1920, 1080));
  // 12 tiles right, less than the 16-tile region: a flight, so the centre moves 1 tile (7 -> 8).
  const ResidencyPlan& plan = residency.plan(orthoView(5100, 2000, 1, 1920, 1080));
  ASSERT_FALSE(plan.visible.empty());
  for (const TileId& id : plan.visible) EXPECT_TRUE(residency.isWanted(id));
  // The visible columns around x = 5100 / 256 = 19.9 lie outside the lagging clip region [0, 16).
  EXPECT_EQ(clipAt(plan, 0).x0, 0);
  EXPECT_FALSE(clipAt(plan, 0).contains(19, 7));
  EXPECT_TRUE(residency.isWanted({0, 0, 19, 7}));
}

TEST(Residency, AJumpOfAWholeRegionMovesTheCentreAtOnce) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.max_centre_step_tiles = 1;
  ResidencyManager residency(info, 0, options);
  residency.plan(orthoView(2000, 2000, 1, 1920, 1080));  // centre 7, region [-1, 15)
  // 39 tiles right: no region between here and there shares a tile with the destination.
  const ResidencyPlan& plan = residency.plan(orthoView(12000, 2000, 1, 1920, 1080));
  EXPECT_EQ(clipAt(plan, 0).x0, 46 - 8);
  EXPECT_TRUE(clipAt(plan, 0).contains(46, 7));
  // Exactly one region (16 tiles) away is a jump too; 15 tiles is a flight of 1 tile a frame.
  EXPECT_EQ(clipAt(residency.plan(orthoView((46 + 16.5) * 256, 2000, 1, 1920, 1080)), 0).x0,
            62 - 8);
  EXPECT_EQ(clipAt(residency.plan(orthoView((62 - 15 + 0.5) * 256, 2000, 1, 1920, 1080)), 0).x0,
            61 - 8);
}

TEST(Residency, CoarsestLevelIsAlwaysWantedFirst) {
  ImageInfo info = imageOf(5000, 3000, 128);  // coarsest level: 1 tile of 79x47 px
  const uint32_t coarsest = info.level_count - 1;
  ResidencyManager residency(info, 0, {});
  for (View view : {orthoView(2500, 1500, 1, 1280, 720), orthoView(100, 2900, 4, 1920, 1080),
                    orthoView(-1e5, 50, 1, 1280, 720), orthoView(2500, 1500, 1.0 / 16, 640, 480)}) {
    const ResidencyPlan& plan = residency.plan(view);
    ASSERT_FALSE(plan.wanted.empty());
    EXPECT_EQ(keyOf(plan.wanted.front().id), (Key{coarsest, 0, 0}));
    EXPECT_FALSE(plan.wanted.front().prefetch);
    for (size_t i = 1; i < plan.wanted.size(); ++i)
      EXPECT_LT(plan.wanted.front().priority, plan.wanted[i].priority);
  }
}

TEST(Residency, WantedListIsSortedAndHoldsEachTileOnce) {
  ImageInfo info = imageOf(5000, 3000, 128);
  ResidencyManager residency(info, 0, {});
  residency.plan(orthoView(2500, 1500, 1, 1280, 720));
  const ResidencyPlan& plan = residency.plan(orthoView(2700, 1500, 1, 1280, 720));
  std::set<Key> seen;
  for (size_t i = 0; i < plan.wanted.size(); ++i) {
    EXPECT_TRUE(seen.insert(keyOf(plan.wanted[i].id)).second) << "duplicate at " << i;
    if (i) {
      EXPECT_LE(plan.wanted[i - 1].priority, plan.wanted[i].priority);
    }
    EXPECT_EQ(residency.priorityOf(plan.wanted[i].id), plan.wanted[i].priority);
  }
}

TEST(Residency, VisibleTilesComeBeforeTheRestOfTheClipRegion) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  const ResidencyPlan& plan = residency.plan(orthoView(8300, 5000, 1, 1920, 1080));
  std::set<Key> visible;
  for (const TileId& id : plan.visible) visible.insert(keyOf(id));
  ASSERT_FALSE(visible.empty());
  double last_visible = -1, first_other = 1e300, first_prefetch = 1e300, last_other = -1;
  for (const TileRequest& r : plan.wanted) {
    if (r.prefetch) {
      first_prefetch = std::min(first_prefetch, r.priority);
      continue;
    }
    if (r.id.level != 0) continue;
    if (visible.count(keyOf(r.id))) {
      last_visible = std::max(last_visible, r.priority);
    } else {
      first_other = std::min(first_other, r.priority);
      last_other = std::max(last_other, r.priority);
    }
  }
  ASSERT_LT(first_other, 1e300) << "the clip region holds more than the visible tiles";
  EXPECT_LT(last_visible, first_other);
  ASSERT_LT(first_prefetch, 1e300) << "the first frame prefetches a ring";
  EXPECT_LT(last_other, first_prefetch);
}

TEST(Residency, CoarseLevelsComeBeforeFineWithinTheVisibleClass) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  residency.plan(orthoView(8300, 5000, 1, 1920, 1080));
  // The tiles under the footprint [7340, 9260] x [4460, 5540] at each level.
  std::map<uint32_t, std::pair<double, double>> range;  // level -> (min, max) priority
  for (uint32_t level = 0; level < info.level_count; ++level) {
    double span = 256.0 * (1 << level);
    for (int64_t y = int64_t(4460 / span); y <= int64_t(5540 / span); ++y)
      for (int64_t x = int64_t(7340 / span); x <= int64_t(9260 / span); ++x) {
        TileId id{0, level, uint32_t(x), uint32_t(y)};
        ASSERT_TRUE(residency.isWanted(id));
        double p = residency.priorityOf(id);
        auto [it, fresh] = range.try_emplace(level, p, p);
        it->second.first = std::min(it->second.first, p);
        it->second.second = std::max(it->second.second, p);
      }
  }
  for (uint32_t level = 1; level < info.level_count; ++level)
    EXPECT_LT(range[level].second, range[level - 1].first) << "level " << level;
}

TEST(Residency, CoarseLevelsComeBeforeFineWithinTheRestOfTheClipRegion) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  const ResidencyPlan& plan = residency.plan(orthoView(8300, 5000, 1, 1920, 1080));
  std::set<Key> visible;
  for (const TileId& id : plan.visible) visible.insert(keyOf(id));
  // Clip-region tiles of levels 0 and 1 that the view does not show.
  double worst_level1 = -1, best_level0 = 1e300;
  TileRect clip1 = clipAt(plan, 1), clip0 = clipAt(plan, 0);
  for (const TileRequest& r : plan.wanted) {
    if (r.prefetch) continue;
    if (r.id.level == 1 && clip1.contains(r.id.x, r.id.y))
      worst_level1 = std::max(worst_level1, r.priority);
    if (r.id.level == 0 && clip0.contains(r.id.x, r.id.y) && !visible.count(keyOf(r.id)))
      best_level0 = std::min(best_level0, r.priority);
  }
  ASSERT_GE(worst_level1, 0);
  ASSERT_LT(best_level0, 1e300);
  EXPECT_LT(worst_level1, best_level0);
}

TEST(Residency, VisibleTilesNearerTheCentreComeFirst) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  residency.plan(orthoView(8320, 5000, 1, 1920, 1080));
  // Tile (32, 19) holds the centre; (29, 19) is three tiles left of it, same class and level.
  EXPECT_LT(residency.priorityOf({0, 0, 32, 19}), residency.priorityOf({0, 0, 29, 19}));
  EXPECT_LT(residency.priorityOf({0, 0, 29, 19}), residency.priorityOf({0, 0, 28, 19}));
}

TEST(Residency, FirstFramePrefetchesTheRingAroundTheClipRegion) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  const ResidencyPlan& plan = residency.plan(orthoView(16.5 * 256, 16.5 * 256, 1, 1920, 1080));
  TileRect clip = clipAt(plan, 0);  // [8, 24)^2
  std::set<Key> expected;
  for (int64_t y = clip.y0 - 1; y <= clip.y1; ++y)
    for (int64_t x = clip.x0 - 1; x <= clip.x1; ++x)
      if (!clip.contains(x, y)) expected.insert({0, uint32_t(x), uint32_t(y)});
  EXPECT_EQ(expected.size(), 4u * 16 + 4);
  EXPECT_EQ(prefetchOf(plan), expected);
}

struct PrefetchCase {
  const char* name;
  double dx, dy;  // move of the view centre, in tiles
};

class DirectionalPrefetch : public testing::TestWithParam<PrefetchCase> {};

TEST_P(DirectionalPrefetch, CrossingATileBoundaryAddsOnlyTheNextRowOrColumnThatWay) {
  const PrefetchCase& c = GetParam();
  ImageInfo info = imageOf(16384, 16384, 256);
  // The prefetch rule alone: the lookahead would make the tiles of that column the view is
  // about to show urgent, and so no longer prefetch (LookaheadWants... covers it).
  ResidencyOptions options;
  options.lookahead_frames = 0;
  ResidencyManager residency(info, 0, options);
  const double t = 256;
  residency.plan(orthoView(16.5 * t, 16.5 * t, 1, 1920, 1080));
  // Half a tile beyond the boundary: inside the effective region, so the clip stays put.
  const ResidencyPlan& plan =
      residency.plan(orthoView((16.5 + c.dx) * t, (16.5 + c.dy) * t, 1, 1920, 1080));
  TileRect clip = clipAt(plan, 0);
  ASSERT_EQ(clip, (TileRect{8, 8, 24, 24}));
  std::set<Key> expected;
  for (int64_t i = 8; i < 24; ++i) {
    if (c.dx > 0) expected.insert({0, 24, uint32_t(i)});
    if (c.dx < 0) expected.insert({0, 7, uint32_t(i)});
    if (c.dy > 0) expected.insert({0, uint32_t(i), 24});
    if (c.dy < 0) expected.insert({0, uint32_t(i), 7});
  }
  EXPECT_EQ(prefetchOf(plan), expected);
}

INSTANTIATE_TEST_SUITE_P(Directions, DirectionalPrefetch,
                         testing::Values(PrefetchCase{"PlusX", 1, 0}, PrefetchCase{"MinusX", -1, 0},
                                         PrefetchCase{"PlusY", 0, 1}, PrefetchCase{"MinusY", 0, -1},
                                         PrefetchCase{"Diagonal", 1, -1}),
                         [](const testing::TestParamInfo<PrefetchCase>& param_info) {
                           return std::string(param_info.param.name);
                         });

TEST(Residency, LookaheadWantsTheTilesAheadOfAPanAsUrgentlyAsTheVisibleOnes) {
  // 64 x 64 tiles of 256 px; a 1920 x 1080 view panning right by 1.5 tiles a frame. The view
  // spans x in [c - 960, c + 960]; six frames ahead its right edge is 9 tiles further on.
  ImageInfo info = imageOf(16384, 16384, 256);
  const double t = 256;
  for (uint32_t frames : {0u, 6u}) {
    SCOPED_TRACE(frames);
    ResidencyOptions options;
    options.lookahead_frames = frames;
    ResidencyManager residency(info, 0, options);
    residency.plan(orthoView(20 * t, 32 * t, 1, 1920, 1080));
    const ResidencyPlan& plan = residency.plan(orthoView(21.5 * t, 32 * t, 1, 1920, 1080));
    // Right edge now: (21.5 * 256 + 960) / 256 = 25.25 -> column 25; in six frames 34.25.
    // Column 16, just left of the view, lies in the clip region [12, 28): wanted, not urgent.
    const TileId ahead{0, 0, 33, 32}, behind{0, 0, 16, 32};
    if (frames == 0) {
      EXPECT_FALSE(residency.isWanted(ahead));
    } else {
      ASSERT_TRUE(residency.isWanted(ahead));
      auto it = std::find_if(plan.wanted.begin(), plan.wanted.end(),
                             [&](const TileRequest& r) { return r.id == ahead; });
      ASSERT_NE(it, plan.wanted.end());
      EXPECT_EQ(it->urgency, 1u);
      EXPECT_FALSE(it->prefetch);
      // Its parent is wanted too, or it could never go up.
      EXPECT_TRUE(residency.isWanted({0, 1, 16, 16}));
    }
    auto behind_request = std::find_if(plan.wanted.begin(), plan.wanted.end(),
                                       [&](const TileRequest& r) { return r.id == behind; });
    ASSERT_NE(behind_request, plan.wanted.end());
    EXPECT_EQ(behind_request->urgency, 2u);  // nothing behind the motion becomes urgent
  }
}

TEST(Residency, TilesOnScreenRankBeforeTheLookaheadsAtEveryLevel) {
  // A fast pan right (3 tiles a frame): the lookahead wants coarse tiles far ahead, but each
  // tile on screen now, fine or coarse, comes first in the plan (and so in the upload budget).
  ImageInfo info = imageOf(16384, 16384, 256);
  const double t = 256;
  ResidencyManager residency(info, 0, {});
  residency.plan(orthoView(20 * t, 32 * t, 1, 1920, 1080));
  const ResidencyPlan& plan = residency.plan(orthoView(23 * t, 32 * t, 1, 1920, 1080));
  // On screen: x in [23 * 256 - 960, 23 * 256 + 960) = columns 19..26 at level 0.
  auto onScreen = [&](const TileId& id) {
    const double span = t * double(1u << id.level);
    return (id.x + 1) * span > 23 * t - 960 && id.x * span < 23 * t + 960 &&
           (id.y + 1) * span > 32 * t - 540 && id.y * span < 32 * t + 540;
  };
  size_t last_on_screen = 0, first_ahead = plan.wanted.size(), ahead = 0;
  for (size_t i = 0; i < plan.wanted.size(); ++i) {
    const TileRequest& request = plan.wanted[i];
    if (request.urgency != 1 || request.id.level == info.level_count - 1) continue;
    if (onScreen(request.id)) {
      last_on_screen = i;
    } else {
      first_ahead = std::min(first_ahead, i);
      ++ahead;
    }
  }
  ASSERT_GT(ahead, 0u) << "the lookahead wanted nothing beyond the screen";
  EXPECT_LT(last_on_screen, first_ahead);
  // Level 0 on screen ranks before level 1 ahead: the one level-0 tile at the far right edge
  // and a level-1 tile two columns beyond it.
  auto rank = [&](const TileId& id) {
    auto it = std::find_if(plan.wanted.begin(), plan.wanted.end(),
                           [&](const TileRequest& r) { return r.id == id; });
    return it == plan.wanted.end() ? SIZE_MAX : size_t(it - plan.wanted.begin());
  };
  const TileId screen_edge{0, 0, 26, 32}, coarse_ahead{0, 1, 15, 16};
  ASSERT_NE(rank(coarse_ahead), SIZE_MAX);
  EXPECT_LT(rank(screen_edge), rank(coarse_ahead));
}

TEST(Residency, AJumpIsNotAVelocityForTheLookahead) {
  ImageInfo info = imageOf(16384, 16384, 256);
  const double t = 256;
  ResidencyManager residency(info, 0, {});
  residency.plan(orthoView(10 * t, 32 * t, 1, 1920, 1080));
  residency.plan(orthoView(40 * t, 32 * t, 1, 1920, 1080));  // 30 tiles in one frame
  // Six more such frames would be far past the image's right edge; nothing beyond the new
  // view's clip region and prefetch ring is wanted at level 0.
  EXPECT_FALSE(residency.isWanted({0, 0, 55, 32}));
}

TEST(Residency, AJumpPrefetchesNothingBeyondTheNewRegion) {
  ImageInfo info = imageOf(16384, 16384, 256);
  const double t = 256;
  ResidencyOptions options;
  options.lookahead_frames = 0;  // the prefetch rule alone, as in DirectionalPrefetch
  ResidencyManager residency(info, 0, options);
  residency.plan(orthoView(10.5 * t, 10.5 * t, 1, 1920, 1080));
  // 30 tiles right and down in one frame: both boundaries crossed, yet no row or column.
  EXPECT_TRUE(prefetchOf(residency.plan(orthoView(40.5 * t, 40.5 * t, 1, 1920, 1080))).empty());
  // One region less a tile is a flight: the crossing prefetches again.
  EXPECT_FALSE(prefetchOf(residency.plan(orthoView(55.5 * t, 40.5 * t, 1, 1920, 1080))).empty());
}

TEST(Residency, MovingWithinATilePrefetchesNothing) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  const double t = 256;
  residency.plan(orthoView(16.1 * t, 16.1 * t, 1, 1920, 1080));
  EXPECT_TRUE(prefetchOf(residency.plan(orthoView(16.9 * t, 16.8 * t, 1, 1920, 1080))).empty());
  EXPECT_TRUE(prefetchOf(residency.plan(orthoView(16.9 * t, 16.8 * t, 1, 1920, 1080))).empty());
}

TEST(Residency, PrefetchIsOffWhenDisabled) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.prefetch = false;
  ResidencyManager residency(info, 0, options);
  EXPECT_TRUE(prefetchOf(residency.plan(orthoView(4200, 4200, 1, 1920, 1080))).empty());
  EXPECT_TRUE(prefetchOf(residency.plan(orthoView(4500, 4200, 1, 1920, 1080))).empty());
}

TEST(Residency, MotionReportsTheCentreOffsetSinceTheLastFrame) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyManager residency(info, 0, {});
  EXPECT_EQ(residency.plan(orthoView(4000, 4000, 1, 1920, 1080)).motion.motion_x, 0);
  const ResidencyPlan& plan = residency.plan(orthoView(4100, 3950, 1, 1920, 1080));
  EXPECT_EQ(plan.motion.motion_x, 100);
  EXPECT_EQ(plan.motion.motion_y, -50);
  EXPECT_EQ(plan.motion.centre_x, 4100);
}

TEST(Residency, KeepsTheClipRegionWithItsMarginAndTheCoarsestLevel) {
  ImageInfo info = imageOf(16384, 16384, 256);
  ResidencyOptions options;
  options.keep_margin_tiles = 2;
  ResidencyManager residency(info, 0, options);
  residency.plan(orthoView(16.5 * 256, 16.5 * 256, 1, 1920, 1080));  // clip [8, 24)^2
  EXPECT_TRUE(residency.isKept({0, 0, 6, 6}));
  EXPECT_TRUE(residency.isKept({0, 0, 25, 16}));
  EXPECT_FALSE(residency.isKept({0, 0, 26, 16}));
  EXPECT_FALSE(residency.isKept({0, 0, 5, 16}));
  EXPECT_TRUE(residency.isKept({0, info.level_count - 1, 0, 0}));
}

}  // namespace
}  // namespace tessera::detail
