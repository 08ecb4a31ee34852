// The analysis phase for one tile: culling never changes a pixel (random overlaps, every
// level, against the brute-force compositor over every candidate), small instances vanish from
// all stored levels together or from none, and the time estimate follows the budget.
#include "analysis/tile_analysis.h"

#include <algorithm>

#include <gtest/gtest.h>

#include "procedural/procedural_fixtures.h"

namespace tessera::detail {
namespace {

std::shared_ptr<const BrushSet> testSet(uint32_t w, uint32_t h) {
  auto set = BrushSet::prepare(tessera::testing::testBrushes(),
                               UnderlyingLayer{tessera::testing::heightLayer(w / 4, h / 4)}, w, h);
  EXPECT_TRUE(set) << set.error().message;
  return *set;
}

std::vector<BrushInstance> candidatesFor(const std::vector<BrushInstance>& all,
                                         const TileGeometry& tile) {
  std::vector<BrushInstance> found;
  for (const BrushInstance& instance : all)
    if (instanceBounds(instance).intersects(tileQueryBox(tile))) found.push_back(instance);
  return found;
}

TEST(TileAnalysis, CullingNeverChangesAPixel) {
  const uint32_t w = 512, h = 384;
  auto set = testSet(w, h);
  AnalysisRules rules;
  rules.small_instance_texels = 0;  // culling alone
  uint64_t covered = 0, candidates_total = 0;
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    // Many opaque base stamps over the soft ones: plenty to cull.
    std::vector<BrushInstance> all = tessera::testing::randomInstances(700, w, h, 7, seed);
    for (size_t i = 0; i < all.size(); i += 3) {
      all[i].brush = 0;
      all[i].opacity = 255;
      all[i].tint_rgba = 0xFFFFFFFF;
    }
    std::sort(all.begin(), all.end(), drawsBefore);
    for (uint32_t level = 0; level < levelCountFor(w, h, 128); ++level) {
      const uint32_t tiles_x = (std::max(1u, w >> level) + 127) / 128;
      const uint32_t tiles_y = (std::max(1u, h >> level) + 127) / 128;
      for (uint32_t ty = 0; ty < tiles_y; ++ty) {
        for (uint32_t tx = 0; tx < tiles_x; ++tx) {
          TileGeometry tile{level, tx, ty, 128, 2, w, h};
          std::vector<BrushInstance> candidates = candidatesFor(all, tile);
          auto analysis = analyseTile(*set, tile, candidates, rules);
          ASSERT_TRUE(analysis) << analysis.error().message;
          Image culled, reference;
          ASSERT_TRUE(compositeTile(*set, tile, analysis->kept, culled, analysis->clips));
          ASSERT_TRUE(compositeTileReference(*set, tile, all, reference));
          ASSERT_EQ(culled.texels, reference.texels)
              << "seed " << seed << " level " << level << " tile " << tx << "," << ty;
          covered += analysis->covered;
          candidates_total += candidates.size();
        }
      }
    }
  }
  EXPECT_GT(covered, candidates_total / 10) << "the test must actually cull";
}

// Left half: levels 0 and 1 are dropped (finest stored level 2); right half: every level.
TEST(TileAnalysis, SmallInstancesVanishFromEveryStoredLevelOrFromNone) {
  const uint32_t w = 1024, h = 512;
  auto set = testSet(w, h);
  DetailMap detail;
  detail.cell_px = 64;
  detail.columns = w / 64;
  detail.rows = h / 64;
  for (uint32_t y = 0; y < detail.rows; ++y)
    for (uint32_t x = 0; x < detail.columns; ++x)
      detail.finest_level.push_back(x < detail.columns / 2 ? 2 : 0);
  AnalysisRules rules;
  rules.detail = &detail;
  rules.small_instance_texels = 0.5;
  std::vector<BrushInstance> all;
  std::mt19937 rng(5);
  for (uint32_t i = 0; i < 400; ++i) {
    BrushInstance instance;
    instance.id = i + 1;
    instance.brush = 1;
    instance.x_px = 8 + rng() % (w - 16);
    instance.y_px = 8 + rng() % (h - 16);
    instance.radius_px = 0.05f + float(rng() % 100) / 100.0f;  // 0.1 .. 2 texels across
    instance.layer = 1;
    all.push_back(instance);
  }
  const uint32_t levels = levelCountFor(w, h, 64);
  size_t dropped_left = 0, kept_right = 0;
  for (const BrushInstance& instance : all) {
    const uint32_t finest = detail.finestLevelIn(instanceBounds(instance));
    int present = 0, stored_levels = 0;
    for (uint32_t level = finest; level < levels; ++level) {
      TileGeometry tile{level,
                        uint32_t(instance.x_px) >> level >> 6,
                        uint32_t(instance.y_px) >> level >> 6,
                        64,
                        0,
                        w,
                        h};
      auto analysis = analyseTile(*set, tile, {&instance, 1}, rules);
      ASSERT_TRUE(analysis);
      ++stored_levels;
      present += analysis->kept.size() + analysis->covered > 0 ? 1 : 0;
    }
    ASSERT_TRUE(present == 0 || present == stored_levels)
        << "instance " << instance.id << " in " << present << " of " << stored_levels << " levels";
    if (finest == 2 && present == 0) ++dropped_left;
    if (finest == 0 && present > 0 && instance.radius_px < 1.0f) ++kept_right;
  }
  EXPECT_GT(dropped_left, 20u);  // tiny where finer levels are dropped: gone
  // Under a texel at levels 1 and up, but not under half a texel at level 0, which is stored
  // there: kept at every level.
  EXPECT_GT(kept_right, 10u);
}

TEST(TileAnalysis, EstimateFollowsTheBudget) {
  auto set = testSet(256, 256);
  std::vector<BrushInstance> all = tessera::testing::randomInstances(300, 256, 256, 5, 9);
  std::sort(all.begin(), all.end(), drawsBefore);
  TileGeometry tile{0, 0, 0, 256, 0, 256, 256};
  AnalysisRules rules;
  rules.tile_budget_ms = 1000;
  auto generous = analyseTile(*set, tile, all, rules);
  ASSERT_TRUE(generous);
  EXPECT_TRUE(generous->within_budget);
  EXPECT_GT(generous->visited_texels, 0u);
  rules.tile_budget_ms = generous->estimated_ms * 0.99;
  auto tight = analyseTile(*set, tile, all, rules);
  ASSERT_TRUE(tight);
  EXPECT_FALSE(tight->within_budget);
}

}  // namespace
}  // namespace tessera::detail
