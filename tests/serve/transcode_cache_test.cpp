// The transcoded-tile cache: least recently used out first, bounded by bytes.
#include "serve/transcode_cache.h"

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

std::shared_ptr<const std::string> body(size_t bytes) {
  return std::make_shared<const std::string>(bytes, 'x');
}

TEST(TranscodeCache, EvictsLeastRecentlyUsedToStayWithinBudget) {
  TranscodeCache cache(300);
  cache.insert("a", body(100));
  cache.insert("b", body(100));
  cache.insert("c", body(100));
  ASSERT_NE(cache.find("a"), nullptr);  // a is now the most recent
  cache.insert("d", body(100));         // evicts b
  EXPECT_EQ(cache.find("b"), nullptr);
  EXPECT_NE(cache.find("a"), nullptr);
  EXPECT_NE(cache.find("c"), nullptr);
  EXPECT_NE(cache.find("d"), nullptr);
  TranscodeCache::Stats stats = cache.stats();
  EXPECT_EQ(stats.bytes, 300u);
  EXPECT_EQ(stats.entries, 3u);
  EXPECT_EQ(stats.evictions, 1u);
  EXPECT_EQ(stats.hits, 4u);
  EXPECT_EQ(stats.misses, 1u);
}

TEST(TranscodeCache, NeverStoresABodyLargerThanTheBudget) {
  TranscodeCache cache(100);
  cache.insert("small", body(60));
  cache.insert("huge", body(101));
  EXPECT_EQ(cache.find("huge"), nullptr);
  EXPECT_NE(cache.find("small"), nullptr);
  EXPECT_EQ(cache.stats().bytes, 60u);
}

TEST(TranscodeCache, ReplacingAKeyAccountsForTheNewSize) {
  TranscodeCache cache(1000);
  cache.insert("k", body(400));
  cache.insert("k", body(100));
  EXPECT_EQ(cache.stats().bytes, 100u);
  EXPECT_EQ(cache.stats().entries, 1u);
  EXPECT_EQ(cache.find("k")->size(), 100u);
}

TEST(TranscodeCache, ZeroBudgetCachesNothing) {
  TranscodeCache cache(0);
  cache.insert("k", body(1));
  EXPECT_EQ(cache.find("k"), nullptr);
  EXPECT_EQ(cache.stats().entries, 0u);
}

}  // namespace
}  // namespace tessera::detail
