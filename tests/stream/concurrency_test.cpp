// Stress for ThreadSanitizer (ctest -L concurrency in the TSan build): the tile cache from many
// threads, the loader pool under rapid re-prioritisation with faults, and TileStreamers
// flying random views over one shared archive while other threads read the cache. Each test
// also checks the invariants that must survive the races: no corrupt tile cached, pins
// respected, the budget kept, and full detail reached once the view settles.
#include <tessera/stream.h>

#include <algorithm>
#include <atomic>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "stream/loader_pool.h"
#include "support/fault_source.h"
#include "support/synthetic_archive.h"

namespace tessera {
namespace {

using test::FaultConfig;
using test::FaultKind;
using test::FaultSource;

uint8_t signatureOf(const TileId& id) {
  return uint8_t(id.x * 31 + id.y * 7 + id.level * 3 + 1);
}

std::shared_ptr<const DecodedTile> makeTile(const TileId& id) {
  auto tile = std::make_shared<DecodedTile>();
  tile->id = id;
  tile->texels = Image(8, 8, 4);
  std::fill(tile->texels.texels.begin(), tile->texels.texels.end(), signatureOf(id));
  return tile;
}

bool intact(const DecodedTile& tile, const TileId& id) {
  return tile.id == id && std::all_of(tile.texels.texels.begin(), tile.texels.texels.end(),
                                      [&](uint8_t v) { return v == signatureOf(id); });
}

class CacheStress : public testing::TestWithParam<bool> {};

TEST_P(CacheStress, InsertFindPinEvictFromManyThreadsKeepsPinsAndBudget) {
  const size_t tile_bytes = makeTile({})->bytes();
  TileCache cache(48 * tile_bytes, GetParam() ? makeViewerShiftPolicy() : makeLruPolicy());
  constexpr int kThreads = 8;
  constexpr int kOps = 3000;
  std::atomic<int> pinned_lost{0}, corrupt{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 random(uint32_t(t) * 7919u + 1);
      auto anyTile = [&] {
        return TileId{0, uint32_t(random() % 3), uint32_t(random() % 12), uint32_t(random() % 12)};
      };
      for (int op = 0; op < kOps; ++op) {
        TileId id = anyTile();
        switch (random() % 7) {
          case 0:
          case 1: (void)cache.insert(makeTile(id)); break;
          case 2:
            if (auto found = cache.find(id); found && !intact(*found, id)) ++corrupt;
            break;
          case 3: {
            std::vector<TileId> ids{id, anyTile(), anyTile()};
            std::vector<std::shared_ptr<const DecodedTile>> pinned;
            cache.findAndPin(ids, pinned);
            for (int i = 0; i < 4; ++i) (void)cache.insert(makeTile(anyTile()));
            for (size_t i = 0; i < ids.size(); ++i) {
              if (!pinned[i]) continue;
              if (!intact(*pinned[i], ids[i])) ++corrupt;
              if (!cache.contains(ids[i])) ++pinned_lost;
              cache.unpin(ids[i]);
            }
            break;
          }
          case 4:
            cache.pin(id);  // may come before the insert: an early pin
            (void)cache.insert(makeTile(anyTile()));
            cache.unpin(id);
            break;
          case 5:
            if (cache.reserve(2 * tile_bytes)) cache.unreserve(2 * tile_bytes);
            break;
          case 6: {
            ViewerMotion motion;
            motion.centre_x = double(random() % 3000);
            motion.centre_y = double(random() % 3000);
            motion.motion_x = double(int(random() % 512) - 256);
            motion.motion_y = double(int(random() % 512) - 256);
            motion.keep_regions.push_back({0, 0, 0, 0, 4, 4});
            cache.setViewerMotion(motion);
            break;
          }
        }
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(corrupt.load(), 0);
  EXPECT_EQ(pinned_lost.load(), 0);
  CacheStats stats = cache.stats();
  EXPECT_LE(stats.peak_bytes, cache.budgetBytes());
  EXPECT_EQ(stats.pinned, 0u);
  EXPECT_EQ(stats.reserved_bytes, 0u);
  EXPECT_EQ(stats.bytes, stats.tiles * tile_bytes);
  EXPECT_GT(stats.evictions, 0u);
}

INSTANTIATE_TEST_SUITE_P(Policies, CacheStress, testing::Values(false, true),
                         [](const testing::TestParamInfo<bool>& param_info) {
                           return std::string(param_info.param ? "ViewerShift" : "Lru");
                         });

class StreamStress : public testing::Test {
 protected:
  void SetUp() override {
    bytes_ = &test::syntheticArchiveBytes({});
    ASSERT_FALSE(bytes_->empty());
    source_ = std::make_shared<FaultSource>(makeMemorySource(*bytes_, "mem:stress.tess"));
    archive_ = test::openArchiveOrFail(source_);
    clean_ = test::openArchiveOrFail(makeMemorySource(*bytes_, "mem:clean.tess"));
    ASSERT_TRUE(archive_ && clean_);
  }
  void TearDown() override {
    if (source_) source_->openGate();
  }

  void expectCachedTilesAreClean(TileCache& cache) {
    for (const TileId& id : test::allTiles(*archive_)) {
      auto cached = cache.find(id);
      if (!cached) continue;
      auto reference = clean_->readTile(id);
      ASSERT_TRUE(reference) << reference.error().message;
      EXPECT_TRUE(cached->texels.texels == reference->texels)
          << "corrupt tile " << id.level << "," << id.x << "," << id.y;
    }
  }

  const std::vector<uint8_t>* bytes_ = nullptr;
  std::shared_ptr<FaultSource> source_;
  std::shared_ptr<Archive> archive_, clean_;
};

TEST_F(StreamStress, LoaderPoolUnderRapidReprioritisationAndFaultsCachesOnlyCleanTiles) {
  TileCache cache(size_t(64) << 20, makeViewerShiftPolicy());
  detail::LoaderOptions options;
  options.threads = 4;
  options.retry_initial = std::chrono::milliseconds(1);
  options.retry_max = std::chrono::milliseconds(2);
  detail::LoaderPool pool(archive_, cache, options);
  std::vector<TileId> tiles = test::allTiles(*archive_);
  source_->setFaults({FaultKind::kFlipBytes, 4, 0, 256});

  std::atomic<bool> done{false};
  std::thread reader([&] {
    std::mt19937 random(99);
    while (!done.load()) {
      const TileId& id = tiles[random() % tiles.size()];
      (void)cache.find(id);
      (void)pool.isRequested(id);
      (void)pool.stats();
      (void)cache.stats();
    }
  });
  std::mt19937 random(5);
  std::vector<detail::LoadEvent> events;
  for (int frame = 0; frame < 300; ++frame) {
    if (frame % 10 == 0) pool.waitIdle();  // let some loads (and faults) happen between frames
    std::vector<TileRequest> wanted;
    for (const TileId& id : tiles)
      if (random() % 4 == 0) wanted.push_back({id, double(random() % 1000), false});
    std::sort(wanted.begin(), wanted.end(),
              [](const TileRequest& a, const TileRequest& b) { return a.priority < b.priority; });
    pool.setWanted(wanted);
    pool.poll(events);
  }
  source_->stopFaulting();
  std::vector<TileRequest> all;
  for (size_t i = 0; i < tiles.size(); ++i) all.push_back({tiles[i], double(i), false});
  pool.setWanted(all);
  auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  auto allCached = [&] {
    return std::all_of(tiles.begin(), tiles.end(),
                       [&](const TileId& id) { return cache.contains(id); });
  };
  while (!allCached() && std::chrono::steady_clock::now() < deadline) {
    pool.waitIdle();
    std::this_thread::yield();
  }
  done = true;
  reader.join();
  EXPECT_TRUE(allCached());
  expectCachedTilesAreClean(cache);
  detail::LoaderStats stats = pool.stats();
  EXPECT_GT(stats.failures, 0u);
  EXPECT_GT(stats.cancelled + stats.stale_dropped, 0u);
}

/// Flies `frames` random views (jumps, zooms, positions partly or wholly off the image, now
/// and then a perspective view) through `streamer`, uploading and releasing like a renderer.
void flyRandomly(TileStreamer& streamer, uint32_t seed, int frames) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> position(-300, 1300), zoom(-2, 4);
  for (int frame = 0; frame < frames; ++frame) {
    View view;
    if (random() % 8 == 0) {
      view.kind = View::Kind::kPerspective;
      view.perspective.eye_x = position(random);
      view.perspective.eye_y = position(random);
      view.perspective.eye_z = 50 + random() % 500;
      view.perspective.yaw_rad = (random() % 628) / 100.0;
      view.perspective.pitch_rad = -0.3 - (random() % 120) / 100.0;
      view.perspective.viewport_w = 320;
      view.perspective.viewport_h = 240;
    } else {
      view.ortho = {position(random), position(random), std::exp2(zoom(random)), 320, 240, 0};
    }
    const FrameUpdate& update = streamer.update(view);
    ApplyResult result;
    for (const auto& tile : update.uploads) result.accepted.push_back(tile->id);
    streamer.acknowledge(result);
  }
}

FrameReport settle(TileStreamer& streamer, const View& view) {
  FrameReport report;
  for (int i = 0; i < 200; ++i) {
    streamer.waitIdleForTesting();
    const FrameUpdate& update = streamer.update(view);
    report = update.report;
    ApplyResult result;
    for (const auto& tile : update.uploads) result.accepted.push_back(tile->id);
    streamer.acknowledge(result);
    if (report.coverage_desired == 1 && report.uploads == 0 && report.queue_length == 0) break;
  }
  return report;
}

TEST_F(StreamStress, TileStreamerUnderRapidViewChangesKeepsItsBudgetAndSettles) {
  StreamerOptions options;
  options.loader_threads = 4;
  const size_t per_tile = archive_->images()[0].storedTileBytes() + sizeof(DecodedTile);
  options.cache_budget_bytes = 200 * per_tile;  // above the wanted set: see the streamer test
  options.retry_initial = std::chrono::milliseconds(1);
  options.retry_max = std::chrono::milliseconds(2);
  auto created = TileStreamer::create(archive_, options);
  ASSERT_TRUE(created) << created.error().message;
  TileStreamer& streamer = **created;

  std::atomic<bool> done{false};
  std::thread reader([&] {
    std::mt19937 random(17);
    const std::vector<TileId> tiles = test::allTiles(*archive_);
    while (!done.load()) {
      auto tile = streamer.cache().find(tiles[random() % tiles.size()]);
      if (tile) {
        auto reference = clean_->readTile(tile->id);
        if (!reference || reference->texels != tile->texels.texels) {
          ADD_FAILURE() << "corrupt tile " << tile->id.level << "," << tile->id.x << ","
                        << tile->id.y;
          return;
        }
      }
      CacheStats stats = streamer.cacheStats();
      if (stats.bytes + stats.reserved_bytes > options.cache_budget_bytes) {
        ADD_FAILURE() << "cache over budget: " << stats.bytes << " + " << stats.reserved_bytes;
        return;
      }
    }
  });
  source_->setFaults({FaultKind::kError, 7});
  flyRandomly(streamer, 1, 150);
  source_->stopFaulting();
  flyRandomly(streamer, 2, 150);
  View still;
  still.ortho = {600, 400, 1, 320, 240, 0};
  FrameReport report = settle(streamer, still);
  done = true;
  reader.join();
  EXPECT_EQ(report.coverage_desired, 1.0);
  EXPECT_TRUE(report.fully_covered);
  EXPECT_LE(streamer.cacheStats().peak_bytes, options.cache_budget_bytes);
  EXPECT_EQ(streamer.state({0, archive_->images()[0].level_count - 1, 0, 0}), TileState::kLocked);
}

TEST_F(StreamStress, SeveralStreamersShareOneArchive) {
  constexpr int kStreamers = 3;
  std::vector<FrameReport> reports(kStreamers);
  std::vector<std::thread> threads;
  for (int i = 0; i < kStreamers; ++i) {
    threads.emplace_back([&, i] {
      StreamerOptions options;
      options.loader_threads = 2;
      options.viewer_shift_eviction = i % 2 == 0;
      options.cache_budget_bytes = size_t(16) << 20;
      auto created = TileStreamer::create(archive_, options);
      if (!created) {
        ADD_FAILURE() << created.error().message;
        return;
      }
      flyRandomly(**created, 100 + uint32_t(i), 100);
      View still;
      still.ortho = {200.0 + 250 * i, 300, 1, 320, 240, 0};
      reports[size_t(i)] = settle(**created, still);
      expectCachedTilesAreClean((*created)->cache());
    });
  }
  for (std::thread& thread : threads) thread.join();
  for (int i = 0; i < kStreamers; ++i) {
    EXPECT_EQ(reports[size_t(i)].coverage_desired, 1.0) << "streamer " << i;
    EXPECT_TRUE(reports[size_t(i)].fully_covered) << "streamer " << i;
  }
}

}  // namespace
}  // namespace tessera
