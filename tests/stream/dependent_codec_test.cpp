// Dependent codecs in the loader (ptm, Marvie & Bouatouch part I): a tile decodes only after its
// parent, against the parent the cache holds, so a child costs the read of its own residual
// payload; missing parents are queued coarsest first; a parent that left the cache is read
// again in the child's job; a corrupt parent fails its children and never yields pixels.
// Orderings are forced by a FaultSource gate, not by timing. Label concurrency: TSan runs it.
#include <algorithm>
#include <map>
#include <set>
#include <tuple>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "stream/loader_pool.h"
#include "support/fault_source.h"
#include "support/synthetic_archive.h"

namespace tessera::detail {
namespace {

using test::FaultSource;

using Key = std::tuple<uint32_t, uint32_t, uint32_t>;  // level, x, y
Key keyOf(const TileId& id) {
  return {id.level, id.x, id.y};
}

test::SyntheticArchiveSpec ptmSpec(uint32_t channels) {
  test::SyntheticArchiveSpec spec;
  spec.width_px = 700;  // odd sizes: partial tiles at every level
  spec.height_px = 461;
  spec.channels = channels;
  spec.codec = Codec::kPtm;
  spec.seed = 11;
  return spec;
}

class DependentCodecTest : public testing::TestWithParam<uint32_t> {
 protected:
  void SetUp() override { open(test::syntheticArchiveBytes(ptmSpec(GetParam()))); }

  void open(const std::vector<uint8_t>& bytes) {
    ASSERT_FALSE(bytes.empty());
    bytes_ = bytes;
    source_ = std::make_shared<FaultSource>(makeMemorySource(bytes_, "mem:ptm.tess"));
    archive_ = test::openArchiveOrFail(source_);
    clean_ = test::openArchiveOrFail(makeMemorySource(bytes_, "mem:clean.tess"));
    ASSERT_TRUE(archive_ && clean_);
    ASSERT_EQ(archive_->images()[0].default_codec, Codec::kPtm);
    ASSERT_GE(archive_->images()[0].level_count, 3u);
    test::warmDirectory(*archive_);
  }

  void TearDown() override {
    if (source_) source_->openGate();
    pool_.reset();
  }

  LoaderPool& start(uint32_t threads) {
    LoaderOptions options;
    options.threads = threads;
    options.read_ahead_bytes = 0;  // every source access is a loader read
    options.merge_gap_bytes = 0;   // and reads nothing but payloads
    options.batch_gap_bytes = 0;
    options.retry_initial = std::chrono::milliseconds(60'000);  // a failure stays failed
    options.retry_max = std::chrono::milliseconds(60'000);
    // Normal-priority workers: under kAuto, on a busy machine, the helpers load again the
    // tiles a starving idle worker holds, and the bytes read exceed the payloads.
    options.priority = LoaderPriority::kNice;
    pool_ = std::make_unique<LoaderPool>(archive_, cache_, options);
    return *pool_;
  }

  static std::vector<TileRequest> requestsFor(const std::vector<TileId>& tiles) {
    std::vector<TileRequest> out;
    for (size_t i = 0; i < tiles.size(); ++i) out.push_back({tiles[i], double(i), false, 1});
    return out;
  }

  TileEntry entryOf(const TileId& id) const {
    auto entry = archive_->tileEntry(id);
    EXPECT_TRUE(entry) << entry.error().message;
    return entry ? *entry : TileEntry{};
  }

  /// An encoded tile of `level` whose parent is encoded too (so both cost a read).
  TileId encodedChildAt(uint32_t level) const {
    for (const TileId& id : test::allTiles(*archive_))
      if (id.level == level && entryOf(id).kind == TileKind::kEncoded &&
          entryOf(Archive::parentTile(id)).kind == TileKind::kEncoded)
        return id;
    ADD_FAILURE() << "no encoded tile with an encoded parent at level " << level;
    return {};
  }

  /// The cached tile equals what the archive decodes on its own, bit for bit.
  void expectCachedExactly(const TileId& id) {
    auto cached = cache_.find(id);
    ASSERT_TRUE(cached) << "tile " << id.level << "," << id.x << "," << id.y << " not cached";
    auto reference = clean_->readTile(id);
    ASSERT_TRUE(reference) << reference.error().message;
    EXPECT_TRUE(cached->texels.texels == reference->texels)
        << "tile " << id.level << "," << id.x << "," << id.y << " differs from the archive";
  }

  /// Bytes the loader read from the source past the directory (every read is logged).
  uint64_t bytesReadFrom(size_t first_access) const {
    std::vector<test::SourceAccess> accesses = source_->accesses();
    uint64_t bytes = 0;
    for (size_t i = first_access; i < accesses.size(); ++i)
      if (!accesses[i].hint) bytes += accesses[i].length_bytes;
    return bytes;
  }

  std::vector<uint8_t> bytes_;
  std::shared_ptr<FaultSource> source_;
  std::shared_ptr<Archive> archive_, clean_;
  TileCache cache_{size_t(256) << 20, makeLruPolicy()};
  std::unique_ptr<LoaderPool> pool_;
};

TEST_P(DependentCodecTest, EveryTileDecodesAfterItsParentAndReadsOnlyItsOwnPayload) {
  LoaderPool& pool = start(4);
  std::vector<TileId> tiles = test::allTiles(*archive_);
  // Finest first: the worst order for a dependent codec. The loader must still decode every
  // parent before its children, from the cache, never by reading a parent twice.
  std::reverse(tiles.begin(), tiles.end());
  uint64_t payload_bytes = 0;
  for (const TileId& id : tiles) payload_bytes += entryOf(id).length_bytes;
  const size_t first_access = source_->accesses().size();
  pool.setWanted(requestsFor(tiles));
  pool.waitIdle();

  std::vector<LoadEvent> events;
  pool.poll(events);
  std::map<Key, size_t> finished_at;
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_TRUE(events[i].ok) << events[i].error;
    finished_at[keyOf(events[i].id)] = i;
  }
  ASSERT_EQ(finished_at.size(), tiles.size());
  const uint32_t coarsest = archive_->images()[0].level_count - 1;
  for (const TileId& id : tiles) {
    expectCachedExactly(id);
    if (id.level < coarsest) {
      EXPECT_LT(finished_at[keyOf(Archive::parentTile(id))], finished_at[keyOf(id)])
          << "tile " << id.level << "," << id.x << "," << id.y << " finished before its parent";
    }
  }
  LoaderStats stats = pool.stats();
  EXPECT_EQ(stats.parents_queued, 0u);  // every parent was wanted already
  EXPECT_EQ(stats.parent_fallbacks, 0u);
  EXPECT_EQ(stats.failures, 0u);
  EXPECT_EQ(bytesReadFrom(first_access), payload_bytes);
  EXPECT_EQ(stats.bytes_read, payload_bytes);
}

TEST_P(DependentCodecTest, AChildWantedAloneQueuesItsMissingAncestorsCoarsestFirst) {
  LoaderPool& pool = start(2);
  const TileId child = encodedChildAt(0);
  pool.setWanted(requestsFor({child}));
  pool.waitIdle();
  std::vector<LoadEvent> events;
  pool.poll(events);
  const uint32_t coarsest = archive_->images()[0].level_count - 1;
  ASSERT_EQ(events.size(), size_t(coarsest) + 1);
  // Coarsest ancestor first, the child last.
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_TRUE(events[i].ok) << events[i].error;
    EXPECT_EQ(events[i].id.level, coarsest - i);
    EXPECT_EQ(events[i].id.x, child.x >> (coarsest - i));
    EXPECT_EQ(events[i].id.y, child.y >> (coarsest - i));
    expectCachedExactly(events[i].id);
  }
  EXPECT_EQ(pool.stats().parents_queued, coarsest);

  // A sibling now costs the read of its own residual payload and nothing else.
  TileId sibling = child;
  if ((child.x ^ 1u) < archive_->images()[0].tilesX(0))
    sibling.x ^= 1;
  else
    sibling.y ^= 1;
  ASSERT_EQ(Archive::parentTile(sibling), Archive::parentTile(child));
  const size_t first_access = source_->accesses().size();
  pool.setWanted(requestsFor({sibling}));
  pool.waitIdle();
  expectCachedExactly(sibling);
  EXPECT_EQ(pool.stats().parents_queued, coarsest);
  EXPECT_EQ(bytesReadFrom(first_access), entryOf(sibling).length_bytes);
}

TEST_P(DependentCodecTest, AChildIsReadWhileItsParentLoadsAndDecodedAfterIt) {
  LoaderPool& pool = start(2);
  const uint32_t coarsest = archive_->images()[0].level_count - 1;
  const TileId child = encodedChildAt(coarsest - 1);
  const TileId parent = Archive::parentTile(child);
  source_->closeGate();
  const size_t first_access = source_->accesses().size();
  pool.setWanted(requestsFor({parent, child}));
  // Both reads wait at the gate at once: the worker without other work started the child's
  // read during the parent's load instead of sleeping until it ended (over a network, one
  // round trip less per level).
  ASSERT_TRUE(source_->waitUntilBlocked(2));
  source_->openGate();
  pool.waitIdle();

  std::vector<LoadEvent> events;
  pool.poll(events);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].id, parent);
  EXPECT_EQ(events[1].id, child);
  for (const LoadEvent& event : events) EXPECT_TRUE(event.ok) << event.error;
  expectCachedExactly(parent);
  expectCachedExactly(child);
  LoaderStats stats = pool.stats();
  EXPECT_EQ(stats.children_read_early, 1u);
  EXPECT_EQ(stats.parent_fallbacks, 0u);  // decoded against the parent the cache received
  EXPECT_EQ(bytesReadFrom(first_access),
            entryOf(parent).length_bytes + entryOf(child).length_bytes);
}

TEST_P(DependentCodecTest, AParentEvictedBeforeItsChildDecodesIsReadAgainInTheChildsJob) {
  LoaderPool& pool = start(1);
  const TileId child = encodedChildAt(0);
  const TileId parent = Archive::parentTile(child);
  std::vector<TileId> ancestors;
  for (TileId id = parent;; id = Archive::parentTile(id)) {
    ancestors.insert(ancestors.begin(), id);
    if (id.level + 1 == archive_->images()[0].level_count) break;
  }
  pool.setWanted(requestsFor(ancestors));
  pool.waitIdle();
  ASSERT_TRUE(cache_.contains(parent));

  // The child's read is held while its parent leaves the cache.
  source_->closeGate();
  pool.setWanted(requestsFor({child}));
  ASSERT_TRUE(source_->waitUntilBlocked(1));
  cache_.erase(parent);
  const size_t first_access = source_->accesses().size();
  source_->openGate();
  pool.waitIdle();

  expectCachedExactly(child);
  LoaderStats stats = pool.stats();
  EXPECT_EQ(stats.parent_fallbacks, 1u);
  EXPECT_EQ(stats.failures, 0u);
  // The parent's payload was read again (its own parent is still cached), and counted.
  EXPECT_EQ(bytesReadFrom(first_access), entryOf(parent).length_bytes);
  EXPECT_FALSE(cache_.contains(parent));  // read for the child, not cached behind the budget
}

TEST_P(DependentCodecTest, ACorruptParentFailsItsChildrenNamingItAndCachesNeither) {
  const TileId child = encodedChildAt(0);
  const TileId parent = Archive::parentTile(child);
  const TileEntry parent_entry = entryOf(parent);
  std::vector<uint8_t> corrupt = bytes_;
  corrupt[parent_entry.offset_bytes + parent_entry.length_bytes / 2] ^= 0x10;
  open(corrupt);
  LoaderPool& pool = start(2);
  pool.setWanted(requestsFor({parent, child}));
  pool.waitIdle();

  std::vector<LoadEvent> events;
  pool.poll(events);
  std::set<Key> failed;
  for (const LoadEvent& event : events) {
    if (event.ok) {
      EXPECT_GT(event.id.level, parent.level) << "only the parent's own ancestors load";
      continue;
    }
    if (event.id == child) {
      EXPECT_NE(event.error.find("its parent cannot be decoded"), std::string::npos) << event.error;
      EXPECT_NE(event.error.find(fmt::format("({},{},{})", parent.level, parent.x, parent.y)),
                std::string::npos)
          << "the error does not name the parent: " << event.error;
    }
    failed.insert(keyOf(event.id));
  }
  EXPECT_TRUE(failed.count(keyOf(parent)));
  EXPECT_TRUE(failed.count(keyOf(child)));
  EXPECT_FALSE(cache_.contains(parent));
  EXPECT_FALSE(cache_.contains(child));
}

INSTANTIATE_TEST_SUITE_P(Channels, DependentCodecTest, testing::Values(1u, 2u, 3u, 4u),
                         [](const testing::TestParamInfo<uint32_t>& param_info) {
                           return fmt::format("c{}", param_info.param);
                         });

}  // namespace
}  // namespace tessera::detail
