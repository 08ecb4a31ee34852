// The tile cache's mechanism: byte budget (reservations included), pins, eviction through the
// policy, replacement and statistics.
#include <tessera/cache.h>

#include <memory>
#include <random>
#include <unordered_map>

#include <gtest/gtest.h>

namespace tessera {
namespace {

TileId tile(uint32_t x, uint32_t y = 0, uint32_t level = 0) {
  return {0, level, x, y};
}

std::shared_ptr<const DecodedTile> makeTile(const TileId& id, uint32_t side_px = 8,
                                            uint8_t fill = 1) {
  auto decoded = std::make_shared<DecodedTile>();
  decoded->id = id;
  decoded->texels = Image(side_px, side_px, 4);
  std::fill(decoded->texels.texels.begin(), decoded->texels.texels.end(), fill);
  return decoded;
}

size_t tileBytes(uint32_t side_px = 8) {
  return makeTile(tile(0), side_px)->bytes();
}

TEST(TileCache, FindReturnsTheInsertedTileAndCountsHitsAndMisses) {
  TileCache cache(10 * tileBytes(), makeLruPolicy());
  auto inserted = makeTile(tile(1), 8, 42);
  ASSERT_TRUE(cache.insert(inserted));
  EXPECT_EQ(cache.find(tile(1)), inserted);
  EXPECT_EQ(cache.find(tile(2)), nullptr);
  EXPECT_EQ(cache.find(tile(1, 0, 1)), nullptr);  // same x, y at another level
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.hits, 1u);
  EXPECT_EQ(stats.misses, 2u);
  EXPECT_EQ(stats.insertions, 1u);
  EXPECT_EQ(stats.tiles, 1u);
  EXPECT_EQ(stats.bytes, tileBytes());
}

TEST(TileCache, ContainsCountsNeitherHitsNorMissesNorUses) {
  TileCache cache(2 * tileBytes(), makeLruPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  ASSERT_TRUE(cache.insert(makeTile(tile(1))));
  EXPECT_TRUE(cache.contains(tile(0)));
  EXPECT_FALSE(cache.contains(tile(5)));
  EXPECT_EQ(cache.stats().hits, 0u);
  EXPECT_EQ(cache.stats().misses, 0u);
  // contains() did not make tile 0 recent: it is still the LRU victim.
  ASSERT_TRUE(cache.insert(makeTile(tile(2))));
  EXPECT_FALSE(cache.contains(tile(0)));
  EXPECT_TRUE(cache.contains(tile(1)));
}

TEST(TileCache, EvictsInPolicyOrderToStayWithinTheBudget) {
  TileCache cache(3 * tileBytes(), makeLruPolicy());
  for (uint32_t x = 0; x < 3; ++x) ASSERT_TRUE(cache.insert(makeTile(tile(x))));
  ASSERT_TRUE(cache.find(tile(0)));
  ASSERT_TRUE(cache.insert(makeTile(tile(3))));
  EXPECT_TRUE(cache.contains(tile(0)));
  EXPECT_FALSE(cache.contains(tile(1)));
  EXPECT_TRUE(cache.contains(tile(2)));
  EXPECT_TRUE(cache.contains(tile(3)));
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.evictions, 1u);
  EXPECT_EQ(stats.tiles, 3u);
  EXPECT_EQ(stats.bytes, 3 * tileBytes());
  EXPECT_LE(stats.peak_bytes, cache.budgetBytes());
}

TEST(TileCache, ALargeTileEvictsAsManySmallOnesAsItNeeds) {
  const size_t big = tileBytes(16), small = tileBytes(8);
  TileCache cache(big + small, makeLruPolicy());
  size_t smalls = (big + small) / small;
  for (uint32_t x = 0; x < smalls; ++x) ASSERT_TRUE(cache.insert(makeTile(tile(x))));
  ASSERT_TRUE(cache.insert(makeTile(tile(100), 16)));
  CacheStats stats = cache.stats();
  EXPECT_LE(stats.bytes, cache.budgetBytes());
  EXPECT_TRUE(cache.contains(tile(100)));
  // The newest small tiles that still fit stay.
  EXPECT_TRUE(cache.contains(tile(uint32_t(smalls - 1))));
  EXPECT_FALSE(cache.contains(tile(0)));
  EXPECT_EQ(stats.tiles + stats.evictions, smalls + 1);
}

TEST(TileCache, TileLargerThanTheWholeBudgetIsRejected) {
  TileCache cache(tileBytes(8), makeLruPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  EXPECT_FALSE(cache.insert(makeTile(tile(1), 16)));
  EXPECT_EQ(cache.stats().rejected, 1u);
  EXPECT_TRUE(cache.contains(tile(0)));
  EXPECT_EQ(cache.stats().evictions, 0u);
}

TEST(TileCache, InsertingTheSameIdReplacesTheTile) {
  TileCache cache(4 * tileBytes(16), makeLruPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0), 8, 1)));
  ASSERT_TRUE(cache.insert(makeTile(tile(0), 16, 2)));
  auto found = cache.find(tile(0));
  ASSERT_TRUE(found);
  EXPECT_EQ(found->texels.width_px, 16u);
  EXPECT_EQ(found->texels.texels[0], 2);
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.tiles, 1u);
  EXPECT_EQ(stats.bytes, tileBytes(16));
  EXPECT_EQ(stats.evictions, 0u);
}

TEST(TileCache, PinnedTilesAreNeverEvicted) {
  TileCache cache(3 * tileBytes(), makeLruPolicy());
  for (uint32_t x = 0; x < 3; ++x) ASSERT_TRUE(cache.insert(makeTile(tile(x))));
  cache.pin(tile(0));  // the LRU victim
  ASSERT_TRUE(cache.insert(makeTile(tile(3))));
  EXPECT_TRUE(cache.contains(tile(0)));
  EXPECT_FALSE(cache.contains(tile(1)));
  EXPECT_EQ(cache.stats().pinned, 1u);
  // Pin everything: nothing can go, the insert is refused and counted.
  cache.pin(tile(2));
  cache.pin(tile(3));
  EXPECT_FALSE(cache.insert(makeTile(tile(4))));
  EXPECT_FALSE(cache.contains(tile(4)));
  for (uint32_t x : {0u, 2u, 3u}) EXPECT_TRUE(cache.contains(tile(x))) << x;
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.rejected, 1u);
  EXPECT_EQ(stats.pinned, 3u);
  EXPECT_LE(stats.bytes, cache.budgetBytes());
}

TEST(TileCache, PinsCountAndTheLastUnpinReleasesTheTile) {
  TileCache cache(1 * tileBytes(), makeLruPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  cache.pin(tile(0));
  cache.pin(tile(0));
  cache.unpin(tile(0));
  EXPECT_FALSE(cache.insert(makeTile(tile(1))));  // still pinned once
  cache.unpin(tile(0));
  EXPECT_EQ(cache.stats().pinned, 0u);
  EXPECT_TRUE(cache.insert(makeTile(tile(1))));
  EXPECT_FALSE(cache.contains(tile(0)));
}

TEST(TileCache, PinBeforeInsertTakesEffectOnInsert) {
  TileCache cache(2 * tileBytes(), makeLruPolicy());
  cache.pin(tile(0));  // e.g. the coarsest level, pinned before it loads
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  EXPECT_EQ(cache.stats().pinned, 1u);
  ASSERT_TRUE(cache.insert(makeTile(tile(1))));
  ASSERT_TRUE(cache.insert(makeTile(tile(2))));
  EXPECT_TRUE(cache.contains(tile(0)));
  EXPECT_FALSE(cache.contains(tile(1)));
}

TEST(TileCache, UnpinBeforeInsertCancelsTheEarlyPin) {
  TileCache cache(1 * tileBytes(), makeLruPolicy());
  cache.pin(tile(0));
  cache.unpin(tile(0));
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  EXPECT_EQ(cache.stats().pinned, 0u);
  EXPECT_TRUE(cache.insert(makeTile(tile(1))));
}

TEST(TileCache, ReplacingAPinnedTileKeepsItPinned) {
  TileCache cache(2 * tileBytes(), makeLruPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  cache.pin(tile(0));
  ASSERT_TRUE(cache.insert(makeTile(tile(0), 8, 9)));
  EXPECT_EQ(cache.stats().pinned, 1u);
  ASSERT_TRUE(cache.insert(makeTile(tile(1))));
  ASSERT_TRUE(cache.insert(makeTile(tile(2))));
  EXPECT_TRUE(cache.contains(tile(0)));
}

TEST(TileCache, FindAndPinPinsEveryHitAndReturnsNullForMisses) {
  TileCache cache(3 * tileBytes(), makeLruPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  ASSERT_TRUE(cache.insert(makeTile(tile(1))));
  std::vector<TileId> ids{tile(1), tile(7), tile(0)};
  std::vector<std::shared_ptr<const DecodedTile>> out;
  cache.findAndPin(ids, out);
  ASSERT_EQ(out.size(), 3u);
  ASSERT_TRUE(out[0]);
  EXPECT_EQ(out[0]->id, tile(1));
  EXPECT_EQ(out[1], nullptr);
  ASSERT_TRUE(out[2]);
  EXPECT_EQ(out[2]->id, tile(0));
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.pinned, 2u);
  EXPECT_EQ(stats.hits, 2u);
  EXPECT_EQ(stats.misses, 1u);
  // Both stay through pressure; only the new ones compete.
  for (uint32_t x = 2; x < 6; ++x) ASSERT_TRUE(cache.insert(makeTile(tile(x))));
  EXPECT_TRUE(cache.contains(tile(0)));
  EXPECT_TRUE(cache.contains(tile(1)));
  cache.unpin(tile(0));
  cache.unpin(tile(1));
  EXPECT_EQ(cache.stats().pinned, 0u);
}

TEST(TileCache, ReservationsCountAgainstTheBudget) {
  const size_t t = tileBytes();
  TileCache cache(4 * t, makeLruPolicy());
  for (uint32_t x = 0; x < 4; ++x) ASSERT_TRUE(cache.insert(makeTile(tile(x))));
  // Two tiles' worth in flight: the two oldest go.
  ASSERT_TRUE(cache.reserve(2 * t));
  EXPECT_FALSE(cache.contains(tile(0)));
  EXPECT_FALSE(cache.contains(tile(1)));
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.reserved_bytes, 2 * t);
  EXPECT_EQ(stats.bytes, 2 * t);
  // A new tile must also fit next to the reservation.
  ASSERT_TRUE(cache.insert(makeTile(tile(4))));
  stats = cache.stats();
  EXPECT_EQ(stats.tiles, 2u);
  EXPECT_LE(stats.bytes + stats.reserved_bytes, cache.budgetBytes());
  EXPECT_LE(stats.peak_bytes, cache.budgetBytes());
  cache.unreserve(2 * t);
  EXPECT_EQ(cache.stats().reserved_bytes, 0u);
  ASSERT_TRUE(cache.insert(makeTile(tile(5))));
  ASSERT_TRUE(cache.insert(makeTile(tile(6))));
  EXPECT_EQ(cache.stats().tiles, 4u);
}

TEST(TileCache, ReserveFailsWhenPinnedTilesOrTheBudgetLeaveNoRoom) {
  const size_t t = tileBytes();
  TileCache cache(2 * t, makeLruPolicy());
  EXPECT_FALSE(cache.reserve(3 * t));
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  ASSERT_TRUE(cache.insert(makeTile(tile(1))));
  cache.pin(tile(0));
  cache.pin(tile(1));
  EXPECT_FALSE(cache.reserve(1));
  EXPECT_EQ(cache.stats().reserved_bytes, 0u);
  cache.unpin(tile(1));
  EXPECT_TRUE(cache.reserve(t));
  EXPECT_FALSE(cache.contains(tile(1)));
}

TEST(TileCache, PeakCountsReservationsAndNeverExceedsTheBudget) {
  const size_t t = tileBytes();
  TileCache cache(5 * t, makeViewerShiftPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  ASSERT_TRUE(cache.reserve(3 * t));
  EXPECT_EQ(cache.stats().peak_bytes, 4 * t);
  cache.unreserve(3 * t);
  EXPECT_EQ(cache.stats().peak_bytes, 4 * t);  // a peak, not the current figure
  for (uint32_t x = 1; x < 20; ++x) {
    ASSERT_TRUE(cache.insert(makeTile(tile(x))));
    ASSERT_TRUE(cache.reserve(t));
    cache.unreserve(t);
  }
  EXPECT_EQ(cache.stats().peak_bytes, 5 * t);
}

TEST(TileCache, EraseRemovesATileRegardlessOfPolicyAndPins) {
  TileCache cache(3 * tileBytes(), makeViewerShiftPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  cache.pin(tile(0));
  cache.erase(tile(0));
  cache.erase(tile(9));  // absent: no effect
  EXPECT_FALSE(cache.contains(tile(0)));
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.tiles, 0u);
  EXPECT_EQ(stats.bytes, 0u);
  EXPECT_EQ(stats.pinned, 0u);
  EXPECT_EQ(stats.evictions, 0u);
}

TEST(TileCache, ReportsThePolicyName) {
  EXPECT_STREQ(TileCache(1, makeLruPolicy()).policyName(), "lru");
  EXPECT_STREQ(TileCache(1, makeViewerShiftPolicy()).policyName(), "viewer-shift");
}

TEST(TileCache, StatsAgreeWithAReferenceModelUnderRandomOperations) {
  const size_t t = tileBytes();
  TileCache cache(16 * t, makeViewerShiftPolicy());
  std::mt19937 random(7);
  std::unordered_map<uint32_t, uint32_t> pins;  // x -> pin count
  uint64_t inserts = 0, hits = 0, misses = 0;
  size_t reserved = 0;
  for (int step = 0; step < 5000; ++step) {
    uint32_t x = random() % 40;
    switch (random() % 6) {
      case 0:
      case 1:
        if (cache.insert(makeTile(tile(x)))) ++inserts;
        break;
      case 2:
        if (cache.find(tile(x)))
          ++hits;
        else
          ++misses;
        break;
      case 3:
        if (cache.contains(tile(x)) && pins[x] < 3) {
          cache.pin(tile(x));
          ++pins[x];
        }
        break;
      case 4:
        if (pins[x] > 0) {
          cache.unpin(tile(x));
          --pins[x];
        }
        break;
      case 5:
        if (reserved == 0 && cache.reserve(2 * t)) {
          reserved = 2 * t;
        } else if (reserved) {
          cache.unreserve(reserved);
          reserved = 0;
        }
        break;
    }
    for (const auto& [px, count] : pins)
      if (count) {
        ASSERT_TRUE(cache.contains(tile(px))) << "pinned tile " << px << " evicted";
      }
    CacheStats stats = cache.stats();
    ASSERT_LE(stats.bytes + stats.reserved_bytes, cache.budgetBytes()) << "step " << step;
    ASSERT_EQ(stats.bytes, stats.tiles * t);
    ASSERT_EQ(stats.reserved_bytes, reserved);
  }
  CacheStats stats = cache.stats();
  EXPECT_EQ(stats.insertions, inserts);
  EXPECT_EQ(stats.hits, hits);
  EXPECT_EQ(stats.misses, misses);
  EXPECT_LE(stats.peak_bytes, cache.budgetBytes());
  EXPECT_GT(stats.evictions, 0u);
  size_t pinned = 0;
  for (const auto& [px, count] : pins) pinned += count > 0;
  EXPECT_EQ(stats.pinned, pinned);
}

TEST(TileCacheDeathTest, UnpinOfAnUnpinnedTileIsABug) {
  TileCache cache(2 * tileBytes(), makeLruPolicy());
  ASSERT_TRUE(cache.insert(makeTile(tile(0))));
  EXPECT_DEATH(cache.unpin(tile(0)), "not pinned");
}

TEST(TileCacheDeathTest, UnreserveOfMoreThanReservedIsABug) {
  TileCache cache(2 * tileBytes(), makeLruPolicy());
  ASSERT_TRUE(cache.reserve(10));
  EXPECT_DEATH(cache.unreserve(11), "more than reserved");
}

}  // namespace
}  // namespace tessera
