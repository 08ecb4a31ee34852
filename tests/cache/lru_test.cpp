// LRU eviction order: inserts and accesses are uses; the least recently used goes first.
#include <tessera/cache.h>

#include <gtest/gtest.h>

namespace tessera {
namespace {

TileId tile(uint32_t x, uint32_t y = 0) {
  return {0, 0, x, y};
}

std::vector<TileId> victimsOf(EvictionPolicy& policy, size_t count) {
  std::vector<TileId> out;
  policy.victims(count, out);
  return out;
}

TEST(LruPolicy, OldestInsertGoesFirst) {
  auto lru = makeLruPolicy();
  EXPECT_STREQ(lru->name(), "lru");
  for (uint32_t x = 0; x < 4; ++x) lru->onInsert(tile(x));
  EXPECT_EQ(victimsOf(*lru, 4), (std::vector<TileId>{tile(0), tile(1), tile(2), tile(3)}));
}

TEST(LruPolicy, AnAccessMakesATileTheMostRecent) {
  auto lru = makeLruPolicy();
  for (uint32_t x = 0; x < 4; ++x) lru->onInsert(tile(x));
  lru->onAccess(tile(0));
  lru->onAccess(tile(2));
  EXPECT_EQ(victimsOf(*lru, 4), (std::vector<TileId>{tile(1), tile(3), tile(0), tile(2)}));
}

TEST(LruPolicy, ReinsertingATileRefreshesIt) {
  auto lru = makeLruPolicy();
  for (uint32_t x = 0; x < 3; ++x) lru->onInsert(tile(x));
  lru->onInsert(tile(0));
  EXPECT_EQ(victimsOf(*lru, 3), (std::vector<TileId>{tile(1), tile(2), tile(0)}));
}

TEST(LruPolicy, ErasedTilesAreNoLongerCandidates) {
  auto lru = makeLruPolicy();
  for (uint32_t x = 0; x < 3; ++x) lru->onInsert(tile(x));
  lru->onErase(tile(0));
  lru->onErase(tile(7));  // unknown: ignored
  EXPECT_EQ(victimsOf(*lru, 3), (std::vector<TileId>{tile(1), tile(2)}));
}

TEST(LruPolicy, ReturnsAtMostCountCandidatesAndAppends) {
  auto lru = makeLruPolicy();
  for (uint32_t x = 0; x < 5; ++x) lru->onInsert(tile(x));
  std::vector<TileId> out{tile(99)};
  lru->victims(2, out);
  EXPECT_EQ(out, (std::vector<TileId>{tile(99), tile(0), tile(1)}));
  EXPECT_TRUE(victimsOf(*lru, 0).empty());
  EXPECT_TRUE(victimsOf(*makeLruPolicy(), 3).empty());
}

TEST(LruPolicy, DistinguishesTilesByEveryAddressField) {
  auto lru = makeLruPolicy();
  const TileId a{0, 1, 2, 3}, b{1, 1, 2, 3}, c{0, 2, 2, 3}, d{0, 1, 3, 2};
  for (const TileId& id : {a, b, c, d}) lru->onInsert(id);
  lru->onAccess(a);
  EXPECT_EQ(victimsOf(*lru, 4), (std::vector<TileId>{b, c, d, a}));
}

}  // namespace
}  // namespace tessera
