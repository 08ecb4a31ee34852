// Mixed archives end to end: built from an SQLite brush database, read back tile by tile
// (procedural tiles composited from their pages, baked ones decoded), every tile equal to the
// brute-force compositor over every instance of the database; corrupt pages and missing brushes
// fail their tile; a bake-all build is a plain 1.0 archive that the reader verifies.
#include <tessera/procedural_build.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/brushes.h>

#include "format/checksum.h"
#include "format/procedural.h"
#include "procedural/procedural_fixtures.h"

namespace tessera {
namespace {

class ProceduralBuildTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("tessera-procbuild-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    database_ = (dir_ / "world.sqlite").string();
    auto db = openSqliteBrushDatabase(database_, true);
    ASSERT_TRUE(db) << db.error().message;
    ASSERT_TRUE((*db)->setTextureExtent({kWidth, kHeight}));
    std::vector<Brush> brushes = testing::testBrushes();
    brushes.erase(brushes.begin() + 5, brushes.end());  // no masks: no --base needed here
    for (const Brush& brush : brushes) ASSERT_TRUE((*db)->addBrush(brush));
    std::vector<BrushInstance> instances =
        testing::randomInstances(600, kWidth, kHeight, uint32_t(brushes.size()), 17);
    for (size_t i = 0; i < instances.size(); i += 4) instances[i].brush = 0;
    auto ids = (*db)->addInstances(instances);
    ASSERT_TRUE(ids) << ids.error().message;
    for (size_t i = 0; i < instances.size(); ++i) instances[i].id = (*ids)[i];
    std::sort(instances.begin(), instances.end(), drawsBefore);
    instances_ = instances;
    auto set = BrushSet::prepare(brushes, {}, kWidth, kHeight);
    ASSERT_TRUE(set);
    reference_set_ = *set;
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  ProceduralBuildOptions options(const std::string& name) {
    ProceduralBuildOptions o;
    o.database = database_;
    o.output = (dir_ / name).string();
    o.tile_size_px = 128;
    o.border_px = 1;
    o.codec = Codec::kZstd;  // lossless: baked tiles compare exactly too
    o.small_instance_texels = 0;
    o.threads = 2;
    o.cost_texel_ns = 8;  // makes the busiest tiles miss the budget, so both kinds occur
    return o;
  }

  static constexpr uint32_t kWidth = 700, kHeight = 500;
  std::filesystem::path dir_;
  std::string database_;
  std::vector<BrushInstance> instances_;
  std::shared_ptr<const BrushSet> reference_set_;
};

TEST_F(ProceduralBuildTest, EveryTileEqualsTheBruteForceCompositor) {
  auto report = buildProceduralArchive(options("mixed.tess"));
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_GT(report->tiles_procedural, 0u);
  EXPECT_GT(report->tiles_baked, 0u);
  EXPECT_GT(report->tiles_over_budget, 0u);
  EXPECT_GT(report->instances_covered, 0u);
  EXPECT_GT(report->bytes_saved, 0);
  EXPECT_LE(report->worst_estimated_ms, report->tile_budget_ms);
  auto archive = Archive::openFile(options("mixed.tess").output);
  ASSERT_TRUE(archive) << archive.error().message;
  auto procedural = ProceduralTiles::open(**archive);
  ASSERT_TRUE(procedural) << procedural.error().message;
  const ImageInfo& info = (*archive)->images()[0];
  uint64_t procedural_tiles = 0;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    for (uint32_t y = 0; y < info.tilesY(level); ++y) {
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        TileId id{0, level, x, y};
        auto entry = (*procedural)->tileEntry(**archive, id);
        ASSERT_TRUE(entry) << entry.error().message;
        Image got;
        if (entry->kind == TileKind::kProcedural) {
          ++procedural_tiles;
          ASSERT_TRUE((*procedural)->compositeTile(**archive, id, *entry, got));
        } else {
          std::vector<uint8_t> payload;
          if (entry->kind == TileKind::kEncoded) {
            auto read = (*archive)->readPayload(id, *entry);
            ASSERT_TRUE(read) << read.error().message;
            payload = std::move(*read);
          }
          auto decoded = (*archive)->decodeTile(id, *entry, payload);
          ASSERT_TRUE(decoded) << decoded.error().message;
          got = std::move(*decoded);
        }
        Image expected;
        ASSERT_TRUE(compositeTileReference(*reference_set_, {level, x, y, 128, 1, kWidth, kHeight},
                                           instances_, expected));
        ASSERT_EQ(got.texels, expected.texels)
            << "tile " << level << "," << x << "," << y << " " << tileKindName(entry->kind);
      }
    }
  }
  EXPECT_EQ(procedural_tiles, report->tiles_procedural);
}

TEST_F(ProceduralBuildTest, CorruptPagesAndMissingBrushesFailTheirTile) {
  ProceduralBuildOptions o = options("mixed.tess");
  o.cost_texel_ns = 0.1;  // every tile may be procedural
  auto report = buildProceduralArchive(o);
  ASSERT_TRUE(report) << report.error().message;
  ASSERT_GT(report->tiles_procedural, 0u);
  auto archive = Archive::openFile(o.output);
  ASSERT_TRUE(archive);
  auto procedural = ProceduralTiles::open(**archive);
  ASSERT_TRUE(procedural);
  TileId id{0, 0, 0, 0};
  auto entry = (*procedural)->tileEntry(**archive, id);
  ASSERT_TRUE(entry);
  ASSERT_EQ(entry->kind, TileKind::kProcedural);
  std::vector<uint8_t> page(entry->length_bytes);
  ASSERT_TRUE((*archive)->source().read(entry->offset_bytes, page));
  Image out;
  ASSERT_TRUE((*procedural)->compositePage(**archive, id, *entry, page, out));
  // A flipped bit fails the checksum.
  std::vector<uint8_t> flipped = page;
  flipped[20] ^= 1;
  auto corrupt = (*procedural)->compositePage(**archive, id, *entry, flipped, out);
  ASSERT_FALSE(corrupt);
  EXPECT_EQ(corrupt.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(corrupt.error().message.find("tile (0,0,0)"), std::string::npos);
  // A page whose checksum matches but that names a brush the archive does not store.
  auto instances = detail::decodeInstancePage(page, 1000, "page");
  ASSERT_TRUE(instances);
  (*instances)[0].brush = 999;
  std::vector<uint8_t> missing = detail::encodeInstancePage(*instances);
  TileEntry forged = *entry;
  forged.checksum = detail::checksum64(missing);
  auto no_brush = (*procedural)->compositePage(**archive, id, forged, missing, out);
  ASSERT_FALSE(no_brush);
  EXPECT_EQ(no_brush.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(no_brush.error().message.find("brush 999"), std::string::npos)
      << no_brush.error().message;
  // Truncated pages.
  for (size_t n = 0; n < page.size(); n += 7) {
    TileEntry short_entry = *entry;
    short_entry.length_bytes = uint32_t(n);
    short_entry.checksum = detail::checksum64({page.data(), n});
    EXPECT_FALSE((*procedural)->compositePage(**archive, id, short_entry, {page.data(), n}, out))
        << n;
  }
}

TEST_F(ProceduralBuildTest, BakeAllWritesAPlainArchiveTheReaderVerifies) {
  ProceduralBuildOptions o = options("baked.tess");
  o.bake_all = true;
  auto report = buildProceduralArchive(o);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tiles_procedural, 0u);
  EXPECT_EQ(report->bytes_saved, 0);
  auto archive = Archive::openFile(o.output);
  ASSERT_TRUE(archive) << archive.error().message;
  VerifyReport verified = (*archive)->verify();
  EXPECT_TRUE(verified.ok()) << (verified.faults.empty() ? "" : verified.faults[0]);
  EXPECT_FALSE(ProceduralTiles::open(**archive));
  auto tile = (*archive)->readTile({0, 1, 1, 1});
  ASSERT_TRUE(tile);
  Image expected;
  ASSERT_TRUE(compositeTileReference(*reference_set_, {1, 1, 1, 128, 1, kWidth, kHeight},
                                     instances_, expected));
  EXPECT_EQ(tile->texels, expected.texels);
}

// A detail region stores no level finer than 1 over the left half: its level-0 tiles are empty,
// the rest of the pyramid is whole.
TEST_F(ProceduralBuildTest, DetailRegionsLeaveFinerLevelsEmpty) {
  ProceduralBuildOptions o = options("detail.tess");
  o.detail_regions = {{{0, 0, 384, 512}, 1}};
  o.small_instance_texels = 0.5;
  auto report = buildProceduralArchive(o);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->tiles_dropped, 3u * 4u);  // columns 0..2 of 128-px tiles, all 4 rows
  auto archive = Archive::openFile(o.output);
  ASSERT_TRUE(archive);
  auto procedural = ProceduralTiles::open(**archive);
  ASSERT_TRUE(procedural) << procedural.error().message;
  for (uint32_t x = 0; x < 6; ++x) {
    auto entry = (*procedural)->tileEntry(**archive, {0, 0, x, 1});
    ASSERT_TRUE(entry);
    EXPECT_EQ(entry->kind == TileKind::kEmpty, x < 3) << x;
  }
}

TEST_F(ProceduralBuildTest, RejectsParentCodedTilesAndMissingDatabases) {
  ProceduralBuildOptions o = options("x.tess");
  o.codec = Codec::kPtm;
  EXPECT_FALSE(buildProceduralArchive(o));
  o = options("x.tess");
  o.database = (dir_ / "missing.sqlite").string();
  auto missing = buildProceduralArchive(o);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("missing.sqlite"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(o.output));
}

}  // namespace
}  // namespace tessera
