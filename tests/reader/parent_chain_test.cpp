// decodeParent, the one walk that gives a parent-coded (ptm) tile its decoded parent: it stops
// at the nearest ancestor the store holds, reads and decodes only the tiles below it (offering
// each to the store), equals what readTile decodes, and fails naming the tile and the ancestor
// that broke the chain.
#include "reader/parent_chain.h"

#include <map>
#include <mutex>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using ::testing::HasSubstr;

/// A store that holds what the test puts in it and records what decodeParent offers.
class MapStore final : public ParentStore {
 public:
  std::shared_ptr<const Image> find(const TileId& id) override {
    std::lock_guard lock(mutex_);
    auto it = held.find(key(id));
    return it == held.end() ? nullptr : it->second;
  }
  void offer(const TileId& id, const std::shared_ptr<const Image>&) override {
    std::lock_guard lock(mutex_);
    offered.push_back(id);
  }
  static uint64_t key(const TileId& id) { return (uint64_t(id.level) << 40) | (id.x << 20) | id.y; }
  std::map<uint64_t, std::shared_ptr<const Image>> held;
  std::vector<TileId> offered;

 private:
  std::mutex mutex_;
};

class ParentChainTest : public testing::Test {
 protected:
  void SetUp() override {
    BuildOptions options;
    options.tile_size_px = 64;
    options.border_px = 1;
    options.codec = Codec::kPtm;
    options.threads = 2;
    built_ = test::buildFromImage(test::makePatternImage(300, 260, 3, 7), options,
                                  test::testTempDir(), "ptm.tess");
    ASSERT_FALSE(built_.bytes.empty());
    archive_ = open(built_.bytes);
    ASSERT_TRUE(archive_);
    ASSERT_GE(archive_->images()[0].level_count, 3u);
  }

  static std::shared_ptr<Archive> open(std::vector<uint8_t> bytes) {
    auto archive = Archive::open(makeMemorySource(std::move(bytes), "ptm.tess"));
    EXPECT_TRUE(archive) << archive.error().message;
    return archive ? *archive : nullptr;
  }

  TileEntry entryOf(const TileId& id) const {
    auto entry = archive_->tileEntry(id);
    EXPECT_TRUE(entry) << entry.error().message;
    return entry ? *entry : TileEntry{};
  }

  /// A level-0 tile whose parent and grandparent are encoded (so each costs a read).
  TileId encodedGrandchild() const {
    const ImageInfo& info = archive_->images()[0];
    for (uint32_t y = 0; y < info.tilesY(0); ++y)
      for (uint32_t x = 0; x < info.tilesX(0); ++x) {
        const TileId id{0, 0, x, y};
        const TileId parent = Archive::parentTile(id);
        if (entryOf(id).kind == TileKind::kEncoded && entryOf(parent).kind == TileKind::kEncoded &&
            entryOf(Archive::parentTile(parent)).kind == TileKind::kEncoded)
          return id;
      }
    ADD_FAILURE() << "no level-0 tile with an encoded parent and grandparent";
    return {};
  }

  test::BuiltArchive built_;
  std::shared_ptr<Archive> archive_;
};

TEST_F(ParentChainTest, AHeldAncestorStopsTheWalkAndOnlyTheTilesBelowItAreRead) {
  const TileId tile = encodedGrandchild();
  const TileId parent = Archive::parentTile(tile);
  const TileId grandparent = Archive::parentTile(parent);
  MapStore store;
  auto held = archive_->readTile(grandparent);
  ASSERT_TRUE(held) << held.error().message;
  store.held[MapStore::key(grandparent)] = std::make_shared<const Image>(std::move(*held));

  ChainReads reads;
  auto decoded = decodeParent(*archive_, tile, store, nullptr, &reads);
  ASSERT_TRUE(decoded) << decoded.error().message;
  auto expected = archive_->readTile(parent);
  ASSERT_TRUE(expected);
  EXPECT_EQ((*decoded)->texels, expected->texels);
  EXPECT_EQ(reads.reads, 1u);
  EXPECT_EQ(reads.bytes_read, entryOf(parent).length_bytes);
  EXPECT_EQ(store.offered, std::vector<TileId>({parent}));
}

TEST_F(ParentChainTest, WithNothingHeldTheChainIsDecodedFromTheCoarsestLevelDown) {
  const TileId tile = encodedGrandchild();
  const uint32_t coarsest = archive_->images()[0].level_count - 1;
  MapStore store;
  ChainReads reads;
  auto decoded = decodeParent(*archive_, tile, store, nullptr, &reads);
  ASSERT_TRUE(decoded) << decoded.error().message;
  auto expected = archive_->readTile(Archive::parentTile(tile));
  ASSERT_TRUE(expected);
  EXPECT_EQ((*decoded)->texels, expected->texels);
  ASSERT_EQ(store.offered.size(), size_t(coarsest));
  uint64_t bytes = 0;
  for (size_t i = 0; i < store.offered.size(); ++i) {
    const uint32_t level = coarsest - uint32_t(i);
    EXPECT_EQ(store.offered[i], (TileId{0, level, tile.x >> level, tile.y >> level}));
    bytes += entryOf(store.offered[i]).length_bytes;
  }
  EXPECT_EQ(reads.bytes_read, bytes);
}

TEST_F(ParentChainTest, ACorruptAncestorFailsNamingTheTileAndTheAncestorAndOffersNothingBelow) {
  const TileId tile = encodedGrandchild();
  const TileId grandparent = Archive::parentTile(Archive::parentTile(tile));
  const TileEntry entry = entryOf(grandparent);
  std::vector<uint8_t> corrupt = built_.bytes;
  test::flipBit(corrupt, entry.offset_bytes + entry.length_bytes / 2, 3);
  archive_ = open(corrupt);
  ASSERT_TRUE(archive_);
  MapStore store;
  auto decoded = decodeParent(*archive_, tile, store, nullptr);
  ASSERT_FALSE(decoded);
  EXPECT_EQ(decoded.error().code, ErrorCode::kCorrupt);
  EXPECT_THAT(
      decoded.error().message,
      HasSubstr(fmt::format("tile (0,{},{}): its parent cannot be decoded", tile.x, tile.y)));
  EXPECT_THAT(decoded.error().message,
              HasSubstr(fmt::format("tile ({},{},{}) checksum mismatch", grandparent.level,
                                    grandparent.x, grandparent.y)));
  for (const TileId& offered : store.offered) EXPECT_GT(offered.level, grandparent.level);
}

}  // namespace
}  // namespace tessera::detail
