// The storage choice against an exhaustive search over every set of stored brushes.
#include "analysis/storage_choice.h"

#include <random>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

// For a set of stored resources the best tiles follow: procedural exactly where eligible,
// cheaper and every resource stored. The optimum is the minimum over all sets.
uint64_t exhaustiveMinimum(const StorageProblem& problem) {
  const size_t resources = problem.resource_bytes.size();
  uint64_t best = UINT64_MAX;
  for (uint32_t set = 0; set < (1u << resources); ++set) {
    uint64_t total = 0;
    for (size_t r = 0; r < resources; ++r)
      if (set & (1u << r)) total += problem.resource_bytes[r];
    for (const StorageTile& tile : problem.tiles) {
      bool available = true;
      for (uint32_t r : tile.resources) available &= (set >> r) & 1;
      bool procedural = available && tile.eligible && tile.procedural_bytes < tile.baked_bytes;
      total += procedural ? tile.procedural_bytes : tile.baked_bytes;
    }
    best = std::min(best, total);
  }
  return best;
}

StorageProblem randomProblem(std::mt19937& rng, size_t resources, size_t tiles) {
  StorageProblem problem;
  for (size_t r = 0; r < resources; ++r) problem.resource_bytes.push_back(rng() % 5000);
  for (size_t t = 0; t < tiles; ++t) {
    StorageTile tile;
    tile.baked_bytes = rng() % 3000;
    tile.procedural_bytes = 48 + rng() % 1500;
    tile.eligible = rng() % 5 != 0;
    for (size_t r = 0; r < resources; ++r)
      if (rng() % 3 == 0) tile.resources.push_back(uint32_t(r));
    problem.tiles.push_back(tile);
  }
  return problem;
}

TEST(StorageChoice, EqualsExhaustiveSearchOnSmallInputs) {
  std::mt19937 rng(2026);
  for (int round = 0; round < 400; ++round) {
    StorageProblem problem = randomProblem(rng, 1 + rng() % 8, 1 + rng() % 40);
    StorageChoice choice = chooseStorage(problem);
    ASSERT_EQ(choice.total_bytes, exhaustiveMinimum(problem)) << "round " << round;
    ASSERT_EQ(choice.total_bytes, storageCost(problem, choice.procedural));
    for (size_t t = 0; t < problem.tiles.size(); ++t) {
      if (!choice.procedural[t]) continue;
      EXPECT_TRUE(problem.tiles[t].eligible);
      for (uint32_t r : problem.tiles[t].resources) EXPECT_TRUE(choice.resource_stored[r]);
    }
  }
}

TEST(StorageChoice, ABrushUsedByOneTileIsNotWorthStoring) {
  StorageProblem problem;
  problem.resource_bytes = {10000, 100};
  problem.tiles = {{2000, 100, true, {0}},
                   {2000, 100, true, {1}},
                   {2000, 100, true, {1}},
                   {2000, 100, false, {1}}};
  StorageChoice choice = chooseStorage(problem);
  EXPECT_EQ(choice.procedural, (std::vector<bool>{false, true, true, false}));
  EXPECT_EQ(choice.resource_stored, (std::vector<bool>{false, true}));
  EXPECT_EQ(choice.total_bytes, 2000u + 100 + 100 + 2000 + 100);
}

}  // namespace
}  // namespace tessera::detail
