// The loader pool over HTTP: a batch's reads travel in one multi-range request where the
// server does them, range by range where it does not, and a bad part fails its tile alone.
// Requests are counted on the server's side (the fault-injecting RangeServer).
#include "stream/loader_pool.h"

#include <algorithm>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/http_source.h>

#include "support/range_server.h"
#include "support/synthetic_archive.h"

namespace tessera::detail {
namespace {

using test::RangeReply;

class LoaderHttpTest : public testing::Test {
 protected:
  LoaderHttpTest() : bytes_(test::syntheticArchiveBytes({})), server_(bytes_, "\"v1\"") {}

  void SetUp() override {
    ASSERT_FALSE(bytes_.empty());
    HttpOptions http;
    http.retry_initial = std::chrono::milliseconds(1);
    http.prefetch_buffer_bytes = 0;  // no fetch-ahead requests: every request is a read's
    auto source = openHttpSource(server_.url(), http);
    ASSERT_TRUE(source) << source.error().message;
    archive_ = test::openArchiveOrFail(*source);
    ASSERT_TRUE(archive_);
    test::warmDirectory(*archive_);
    tiles_ = everyOtherTile();
    ASSERT_GE(tiles_.size(), 6u);
  }

  void TearDown() override { pool_.reset(); }

  /// One worker, whose first batch takes every wanted tile (they lie within batch_gap_bytes
  /// of each other), each tile its own range (merge gap 0, and a tile's payload between two).
  LoaderPool& start() {
    LoaderOptions options;
    options.threads = 1;
    options.priority = LoaderPriority::kNice;
    options.merge_gap_bytes = 0;
    options.read_ahead_bytes = 0;
    options.retry_initial = std::chrono::seconds(60);  // a failed tile stays failed here
    pool_ = std::make_unique<LoaderPool>(archive_, cache_, options);
    return *pool_;
  }

  /// Eight encoded tiles of level 0, every other one in file order, so no two are adjacent.
  std::vector<TileId> everyOtherTile() const {
    std::vector<std::pair<uint64_t, TileId>> by_offset;
    for (const TileId& id : test::allTiles(*archive_)) {
      auto entry = archive_->tileEntry(id);
      if (id.level == 0 && entry && entry->kind == TileKind::kEncoded)
        by_offset.emplace_back(entry->offset_bytes, id);
    }
    std::sort(by_offset.begin(), by_offset.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<TileId> out;
    for (size_t i = 0; i < by_offset.size() && out.size() < 8; i += 2)
      out.push_back(by_offset[i].second);
    return out;
  }

  /// Loads tiles_ and returns the load events, by tile in tiles_ order.
  std::vector<LoadEvent> load(LoaderPool& pool) {
    std::vector<TileRequest> requests;
    for (size_t i = 0; i < tiles_.size(); ++i) requests.push_back({tiles_[i], double(i), false});
    pool.setWanted(requests);
    pool.waitIdle();
    std::vector<LoadEvent> events;
    pool.poll(events);
    std::vector<LoadEvent> ordered;
    for (const TileId& id : tiles_) {
      auto it = std::find_if(events.begin(), events.end(),
                             [&](const LoadEvent& event) { return event.id == id; });
      if (it != events.end()) ordered.push_back(*it);
    }
    EXPECT_EQ(ordered.size(), tiles_.size());
    return ordered;
  }

  /// Requests the server saw from index `from` on.
  std::vector<test::SeenRequest> seenSince(size_t from) const {
    std::vector<test::SeenRequest> seen = server_.seen();
    return {seen.begin() + std::ptrdiff_t(std::min(from, seen.size())), seen.end()};
  }

  /// The first tile in file order: the server's first part.
  TileId lowestTile() const { return tiles_.front(); }

  std::vector<uint8_t> bytes_;
  test::RangeServer server_;
  std::shared_ptr<Archive> archive_;
  std::vector<TileId> tiles_;
  TileCache cache_{size_t(64) << 20, makeLruPolicy()};
  std::unique_ptr<LoaderPool> pool_;
};

TEST_F(LoaderHttpTest, ABatchTravelsInOneMultiRangeRequest) {
  server_.setPlan([](uint64_t) { return RangeReply{RangeReply::Kind::kMultipart}; });
  LoaderPool& pool = start();
  const size_t before = server_.seen().size();
  for (const LoadEvent& event : load(pool)) EXPECT_TRUE(event.ok) << event.error;
  const std::vector<test::SeenRequest> seen = seenSince(before);
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_EQ(size_t(std::count(seen[0].range.begin(), seen[0].range.end(), ',')), tiles_.size() - 1)
      << seen[0].range;
  EXPECT_EQ(pool.stats().reads, tiles_.size());
  for (const TileId& id : tiles_) EXPECT_TRUE(cache_.contains(id));
}

TEST_F(LoaderHttpTest, AServerWithoutMultiRangeStillLoadsEveryTileAndIsRemembered) {
  LoaderPool& pool = start();  // the default plan answers the first range of several only
  const size_t before = server_.seen().size();
  for (const LoadEvent& event : load(pool)) EXPECT_TRUE(event.ok) << event.error;
  std::vector<test::SeenRequest> seen = seenSince(before);
  ASSERT_EQ(seen.size(), 1 + tiles_.size());  // the refused request, then one per tile
  EXPECT_NE(seen[0].range.find(','), std::string::npos);
  for (size_t i = 1; i < seen.size(); ++i)
    EXPECT_EQ(seen[i].range.find(','), std::string::npos) << seen[i].range;
  // Remembered: the next batch asks range by range from the start.
  for (const TileId& id : tiles_) cache_.erase(id);
  const size_t again = server_.seen().size();
  pool.setWanted({});
  for (const LoadEvent& event : load(pool)) EXPECT_TRUE(event.ok) << event.error;
  seen = seenSince(again);
  ASSERT_EQ(seen.size(), tiles_.size());
  for (const test::SeenRequest& request : seen)
    EXPECT_EQ(request.range.find(','), std::string::npos) << request.range;
}

TEST_F(LoaderHttpTest, AMislabelledOrCorruptPartFailsOnlyItsTile) {
  for (auto kind :
       {RangeReply::Kind::kMultipartFirstMislabelled, RangeReply::Kind::kMultipartFirstCorrupt}) {
    SCOPED_TRACE(int(kind));
    server_.setPlan([kind](uint64_t) { return RangeReply{kind}; });
    for (const TileId& id : tiles_) cache_.erase(id);
    LoaderPool& pool = start();
    const size_t before = server_.seen().size();
    const std::vector<LoadEvent> events = load(pool);
    ASSERT_EQ(events.size(), tiles_.size());
    EXPECT_EQ(seenSince(before).size(), 1u);
    ASSERT_EQ(events[0].id, lowestTile());
    EXPECT_FALSE(events[0].ok);
    EXPECT_FALSE(cache_.contains(lowestTile()));
    EXPECT_NE(events[0].error.find(kind == RangeReply::Kind::kMultipartFirstCorrupt
                                       ? "checksum"
                                       : "no part holding bytes"),
              std::string::npos)
        << events[0].error;
    EXPECT_NE(events[0].error.find(
                  fmt::format("({},{},{})", lowestTile().level, lowestTile().x, lowestTile().y)),
              std::string::npos)
        << events[0].error;
    for (size_t i = 1; i < events.size(); ++i) {
      EXPECT_TRUE(events[i].ok) << events[i].error;
      EXPECT_TRUE(cache_.contains(tiles_[i]));
    }
    pool_.reset();
  }
}

}  // namespace
}  // namespace tessera::detail
