// Archive is thread-safe after open: many threads reading tiles (sharing the page cache)
// see exactly what one thread sees. Run under ThreadSanitizer in CI (label "concurrency").
#include <tessera/archive.h>
#include <tessera/link.h>

#include <algorithm>
#include <barrier>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "format/checksum.h"
#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera {
namespace {

TEST(ArchiveConcurrency, ManyThreadsReadEveryTileConsistently) {
  BuildOptions options;
  options.tile_size_px = 64;
  options.border_px = 2;
  options.codec = Codec::kZstd;
  options.threads = 2;
  options.page_tiles_log2 = 3;  // many small pages, so threads race to fill the page cache
  test::BuiltArchive built =
      test::buildFromImage(test::makePatternImage(1100, 700, 4, 3), options, test::testTempDir());
  auto opened = Archive::openFile(built.path);
  ASSERT_TRUE(opened) << opened.error().message;
  std::shared_ptr<Archive> archive = *opened;
  const ImageInfo info = archive->images()[0];
  std::vector<TileId> tiles;
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) tiles.push_back({0, level, x, y});

  // Expected: checksums of each tile's texels, from a second archive object on one thread.
  auto single = Archive::openFile(built.path);
  ASSERT_TRUE(single);
  std::vector<uint64_t> expected;
  for (const TileId& tile : tiles)
    expected.push_back(detail::checksum64((*single)->readTile(tile)->texels));

  constexpr int kThreads = 8;
  std::vector<int> mismatches(kThreads, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::vector<size_t> order(tiles.size());
      for (size_t i = 0; i < order.size(); ++i) order[i] = i;
      std::shuffle(order.begin(), order.end(), std::mt19937(t));
      for (int pass = 0; pass < 2; ++pass) {
        for (size_t i : order) {
          auto tile = archive->readTile(tiles[i]);
          if (!tile || detail::checksum64(tile->texels) != expected[i]) ++mismatches[t];
        }
        auto region = archive->readRegion(0, 0, {int64_t(t) * 50, 30, 300, 200});
        if (!region) ++mismatches[t];
      }
    });
  }
  for (auto& thread : threads) thread.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(mismatches[t], 0) << "thread " << t;
}

// A region of many tiles is decoded by a thread per core: it must equal the tiles assembled
// one by one, and with damaged tiles report the first in row-major order, as one thread would.
TEST(ArchiveConcurrency, RegionsReadInParallelEqualTheirTilesAndReportTheFirstFault) {
  BuildOptions options;
  options.tile_size_px = 64;
  options.border_px = 1;
  options.codec = Codec::kZstd;
  options.threads = 2;
  const Image source = test::makePatternImage(1100, 700, 3, 5);
  test::BuiltArchive built = test::buildFromImage(source, options, test::testTempDir());
  auto opened = Archive::openFile(built.path);
  ASSERT_TRUE(opened) << opened.error().message;
  const PixelRect rect{37, 21, 1000, 650};  // about 16 x 11 tiles, unaligned on every side
  auto region = (*opened)->readRegion(0, 0, rect);
  ASSERT_TRUE(region) << region.error().message;
  for (uint32_t y = 0; y < rect.height; ++y)
    ASSERT_TRUE(std::equal(region->row(y), region->row(y) + region->strideBytes(),
                           source.row(uint32_t(rect.y) + y) + size_t(rect.x) * 3))
        << "row " << y;

  // Damage two tiles inside the region; the one earlier in row-major order is reported.
  const TileId first{0, 0, 5, 3}, later{0, 0, 2, 7};
  std::vector<uint8_t> bytes = test::readFileBytes(built.path);
  for (const TileId& tile : {first, later}) {
    const TileEntry entry = *(*opened)->tileEntry(tile);
    ASSERT_EQ(entry.kind, TileKind::kEncoded);
    bytes[entry.offset_bytes + entry.length_bytes / 2] ^= 0x5a;
  }
  test::writeFileBytes(built.path + ".damaged", bytes);
  auto damaged = Archive::openFile(built.path + ".damaged");
  ASSERT_TRUE(damaged) << damaged.error().message;
  for (int run = 0; run < 4; ++run) {
    auto failed = (*damaged)->readRegion(0, 0, rect);
    ASSERT_FALSE(failed);
    EXPECT_NE(failed.error().message.find("tile (0,5,3)"), std::string::npos)
        << failed.error().message;
  }
}

TEST(ArchiveConcurrency, ConcurrentVerifyAndReadsAgree) {
  BuildOptions options;
  options.tile_size_px = 64;
  options.codec = Codec::kLz4;
  options.threads = 2;
  test::BuiltArchive built =
      test::buildFromImage(test::makePatternImage(500, 400, 3, 1), options, test::testTempDir());
  auto archive = Archive::open(makeMemorySource(built.bytes, "c.tess"));
  ASSERT_TRUE(archive);
  std::vector<int> faults(4, -1);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] { faults[t] = int((*archive)->verify().fault_count); });
  for (auto& thread : threads) thread.join();
  for (int f : faults) EXPECT_EQ(f, 0);
}

TEST(ArchiveConcurrency, ThreadsDecodingPtmTilesShareTheDecodedParents) {
  // Every ptm tile below the coarsest level decodes against its parent, which the threads
  // obtain through the archive's one cache of decoded parents: each in its own shuffled order,
  // so they race to decode the same chains and fill the cache at once.
  BuildOptions options;
  options.tile_size_px = 64;
  options.border_px = 1;
  options.codec = Codec::kPtm;
  options.threads = 2;
  test::BuiltArchive built =
      test::buildFromImage(test::makePatternImage(700, 500, 3, 9), options, test::testTempDir());
  auto archive = Archive::open(makeMemorySource(built.bytes, "ptm.tess"));
  ASSERT_TRUE(archive) << archive.error().message;
  auto single = Archive::open(makeMemorySource(built.bytes, "single.tess"));
  ASSERT_TRUE(single);
  const ImageInfo info = (*archive)->images()[0];
  ASSERT_GE(info.level_count, 3u);
  std::vector<TileId> tiles;
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) tiles.push_back({0, level, x, y});
  std::vector<uint64_t> expected;
  for (const TileId& tile : tiles) {
    auto texels = (*single)->readTile(tile);
    ASSERT_TRUE(texels) << texels.error().message;
    expected.push_back(detail::checksum64(texels->texels));
  }

  constexpr int kThreads = 6;
  std::barrier start(kThreads);
  std::vector<int> mismatches(kThreads, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      std::vector<size_t> order(tiles.size());
      for (size_t i = 0; i < order.size(); ++i) order[i] = i;
      std::shuffle(order.begin(), order.end(), std::mt19937(100 + t));
      start.arrive_and_wait();
      for (size_t i : order) {
        auto tile = (*archive)->readTile(tiles[i]);
        if (!tile || detail::checksum64(tile->texels) != expected[i]) ++mismatches[t];
      }
    });
  for (auto& thread : threads) thread.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(mismatches[t], 0) << "thread " << t;
}

TEST(ArchiveConcurrency, ThreadsWantingTheSamePageReadItOnce) {
  // After a jump every loader thread looks up tiles of the same directory pages at once; over
  // a network each duplicate page read costs a round trip and the page's bytes. Behind a
  // simulated link with a 100 ms round trip, eight threads starting together all ask while the
  // first read is on its way: they must wait for it, not read the page again.
  BuildOptions options;
  options.tile_size_px = 64;
  options.codec = Codec::kZstd;
  options.threads = 2;
  options.page_tiles_log2 = 3;
  test::BuiltArchive built =
      test::buildFromImage(test::makePatternImage(1100, 700, 4, 3), options, test::testTempDir());
  auto file = openFileSource(built.path);
  ASSERT_TRUE(file);
  // The reads one thread needs for one lookup (page index and page, or fewer when they lie in
  // the header region read at open).
  auto alone_link = makeThrottledSource(*file, {1e9, 0});
  auto alone = Archive::open(alone_link);
  ASSERT_TRUE(alone);
  const uint64_t opened_reads = alone_link->totals().reads;
  ASSERT_TRUE((*alone)->tileEntry({0, 0, 0, 0}));
  const uint64_t one_lookup = alone_link->totals().reads - opened_reads;

  auto link = makeThrottledSource(*file, {1e9, 0.1});
  auto archive = Archive::open(link);
  ASSERT_TRUE(archive);
  const uint64_t before = link->totals().reads;
  constexpr int kThreads = 8;
  std::barrier start(kThreads);
  std::vector<std::thread> threads;
  std::vector<int> failures(kThreads, 0);
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      start.arrive_and_wait();
      // Tiles (t % 8, t / 8) all lie in page (0, 0) of level 0 (8 x 8 tiles a page).
      if (!(*archive)->tileEntry({0, 0, uint32_t(t % 8), uint32_t(t / 8)})) ++failures[t];
    });
  for (std::thread& thread : threads) thread.join();
  for (int f : failures) EXPECT_EQ(f, 0);
  EXPECT_EQ(link->totals().reads - before, one_lookup);
}

}  // namespace
}  // namespace tessera
