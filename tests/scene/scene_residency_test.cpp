// The residency policy: chains of levels, loads by missed screen, the budget and the order of
// eviction.
#include "scene_residency.h"

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

// Three textures of four levels: 4096, 1024, 256 bytes and a 64-byte coarsest.
SceneResidency threeTextures() {
  const std::vector<uint64_t> levels{4096, 1024, 256, 64};
  return SceneResidency({levels, levels, levels});
}

void loadTo(SceneResidency& r, uint32_t texture, uint32_t level) {
  while (r.resident(texture) > level) ASSERT_TRUE(r.loaded({texture, r.resident(texture) - 1}));
}

TEST(SceneResidency, CoarsestIsResidentFromTheStartAndPinned) {
  SceneResidency r = threeTextures();
  for (uint32_t t = 0; t < 3; ++t) EXPECT_EQ(r.resident(t), 3u);
  EXPECT_EQ(r.pinnedBytes(), 3u * 64);
  EXPECT_EQ(r.budgetedBytes(), 0u);
  loadTo(r, 0, 0);
  EXPECT_TRUE(r.evictTo(0).size() == 3);
  EXPECT_EQ(r.resident(0), 3u) << "eviction stops at the coarsest";
  EXPECT_EQ(r.budgetedBytes(), 0u);
}

TEST(SceneResidency, LevelsExtendTheChainOneAtATime) {
  SceneResidency r = threeTextures();
  EXPECT_FALSE(r.loaded({0, 1})) << "level 1 before level 2 is refused";
  EXPECT_TRUE(r.loaded({0, 2}));
  EXPECT_FALSE(r.loaded({0, 2})) << "a duplicate is refused";
  EXPECT_EQ(r.budgetedBytes(), 256u);
}

TEST(SceneResidency, LoadsGoToWhatTheScreenMissesMost) {
  SceneResidency r = threeTextures();
  // Texture 0: 100 px missing 3 levels (300); texture 1: 1000 px missing 1 (1000);
  // texture 2: 150 px missing 2 (300, ties broken by index).
  r.setDemand({{0, 0, 100}, {1, 2, 1000}, {2, 1, 150}});
  const std::vector<LevelRef> loads = r.nextLoads(1 << 20, {});
  ASSERT_EQ(loads.size(), 3u);
  EXPECT_EQ(loads[0], (LevelRef{1, 2}));
  EXPECT_EQ(loads[1], (LevelRef{0, 2}));
  EXPECT_EQ(loads[2], (LevelRef{2, 2}));
  // A busy texture waits; a level that cannot fit the budget is not asked for.
  EXPECT_EQ(r.nextLoads(1 << 20, {false, true, false}).size(), 2u);
  EXPECT_TRUE(r.nextLoads(255, {}).empty());
}

TEST(SceneResidency, DemandsOfOneTextureMergeToTheFinestLevel) {
  SceneResidency r = threeTextures();
  r.setDemand({{0, 2, 10}, {0, 1, 20}});
  EXPECT_EQ(r.wanted(0), 1u);
  r.setDemand({});
  EXPECT_EQ(r.wanted(0), 3u) << "out of view: its coarsest";
}

TEST(SceneResidency, EvictsUnwantedOldestFirstThenTheLeastSeen) {
  SceneResidency r = threeTextures();
  r.setDemand({{0, 1, 10}, {1, 1, 500}, {2, 1, 20}});  // frame 1: all three wanted at level 1
  for (uint32_t t = 0; t < 3; ++t) loadTo(r, t, 1);
  EXPECT_EQ(r.budgetedBytes(), 3u * (1024 + 256));
  r.setDemand({{1, 1, 500}, {2, 1, 20}});  // frame 2: texture 0 leaves the view
  r.setDemand({{1, 1, 500}});              // frame 3: texture 2 leaves the view
  // Unwanted first, oldest seen first (texture 0, then 2), finest level first; then the
  // wanted texture 1.
  const std::vector<LevelRef> dropped = r.evictTo(256);
  const std::vector<LevelRef> expected{{0, 1}, {0, 2}, {2, 1}, {2, 2}, {1, 1}};
  EXPECT_EQ(dropped, expected);
  EXPECT_LE(r.budgetedBytes(), 256u);
  EXPECT_EQ(r.resident(1), 2u);
}

TEST(SceneResidency, WantedLevelsOfTheFewestPixelsGoFirst) {
  SceneResidency r = threeTextures();
  r.setDemand({{0, 2, 300}, {1, 2, 100}, {2, 2, 200}});
  for (uint32_t t = 0; t < 3; ++t) loadTo(r, t, 2);
  const std::vector<LevelRef> dropped = r.evictTo(256);
  const std::vector<LevelRef> expected{{1, 2}, {2, 2}};
  EXPECT_EQ(dropped, expected);
}

}  // namespace
}  // namespace tessera::detail
