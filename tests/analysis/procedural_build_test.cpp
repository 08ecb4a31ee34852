// Mixed archives end to end: built from an SQLite brush database, read back tile by tile
// (procedural tiles composited from their pages, baked ones decoded), every tile equal to the
// brute-force compositor over every instance of the database, through Archive's own read path
// (with and without a --base layer); corrupt pages, damaged brush images and missing brushes
// fail their tiles (never a wrong picture); a bake-all build is a plain 1.0 archive that the
// reader verifies.
#include <tessera/procedural_build.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/brushes.h>

#include <tessera/picture_file.h>

#include "format/checksum.h"
#include "format/header.h"
#include "format/procedural.h"
#include "format/sections.h"
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
  const ImageInfo& info = (*archive)->images()[0];
  uint64_t procedural_tiles = 0;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    for (uint32_t y = 0; y < info.tilesY(level); ++y) {
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        // The reader's own path: the entry from its directory page, then readTile, which
        // composites procedural tiles and decodes baked ones.
        TileId id{0, level, x, y};
        auto entry = (*archive)->tileEntry(id);
        ASSERT_TRUE(entry) << entry.error().message;
        procedural_tiles += entry->kind == TileKind::kProcedural;
        auto read = (*archive)->readTile(id);
        ASSERT_TRUE(read) << read.error().message;
        const Image& got = *read;
        Image expected;
        ASSERT_TRUE(compositeTileReference(*reference_set_, {level, x, y, 128, 1, kWidth, kHeight},
                                           instances_, expected));
        ASSERT_EQ(got.texels, expected.texels)
            << "tile " << level << "," << x << "," << y << " " << tileKindName(entry->kind);
      }
    }
  }
  EXPECT_EQ(procedural_tiles, report->tiles_procedural);
  VerifyReport verified = (*archive)->verify();
  EXPECT_TRUE(verified.ok()) << (verified.faults.empty() ? "" : verified.faults[0]);
  uint64_t tiles = 0;
  for (uint32_t level = 0; level < info.level_count; ++level)
    tiles += uint64_t(info.tilesX(level)) * info.tilesY(level);
  EXPECT_EQ(verified.tiles_checked, tiles);
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
  auto entry = (*archive)->tileEntry(id);
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
  for (uint32_t x = 0; x < 6; ++x) {
    auto entry = (*archive)->tileEntry({0, 0, x, 1});
    ASSERT_TRUE(entry);
    EXPECT_EQ(entry->kind == TileKind::kEmpty, x < 3) << x;
  }
}

// Reads a file whole; the tests below damage archives byte by byte.
std::vector<uint8_t> readFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void flipByte(const std::string& path, uint64_t offset) {
  std::fstream file(path, std::ios::binary | std::ios::in | std::ios::out);
  file.seekg(std::streamoff(offset));
  char byte = 0;
  file.read(&byte, 1);
  byte = char(byte ^ 0x5A);
  file.seekp(std::streamoff(offset));
  file.write(&byte, 1);
}

// The procedural directory of a mixed archive file, found the way a reader finds it.
detail::ProceduralDirectory proceduralDirectoryOf(const std::string& path) {
  const std::vector<uint8_t> file = readFileBytes(path);
  auto header = detail::decodeHeader(file, path);
  EXPECT_TRUE(header);
  auto table = detail::decodeSectionTableRef(file, *header, path);
  EXPECT_TRUE(table && table->length_bytes > 0);
  auto sections = detail::decodeSectionTable(
      {file.data() + table->offset_bytes, table->length_bytes}, *header, path);
  EXPECT_TRUE(sections);
  auto ref = detail::decodeProceduralRef(*sections, path);
  EXPECT_TRUE(ref && ref->length_bytes > 0);
  auto directory = detail::decodeProceduralDirectory(
      {file.data() + ref->offset_bytes, ref->length_bytes}, *header, header->image_count, path);
  EXPECT_TRUE(directory);
  return *directory;
}

// Item 3: a damaged instance page fails its tile through the reader's own path (readTile,
// verify), with the tile named; tiles on other pages still read, equal to the reference.
TEST_F(ProceduralBuildTest, ArchiveFailsOnlyTheTileWhosePageIsCorrupt) {
  ProceduralBuildOptions o = options("mixed.tess");
  o.cost_texel_ns = 0.1;  // every tile may be procedural
  ASSERT_TRUE(buildProceduralArchive(o));
  TileId damaged{0, 0, 0, 0}, intact{0, 0, 3, 2};
  TileEntry damaged_entry, intact_entry;
  {
    auto archive = Archive::openFile(o.output);
    ASSERT_TRUE(archive) << archive.error().message;
    damaged_entry = *(*archive)->tileEntry(damaged);
    intact_entry = *(*archive)->tileEntry(intact);
    ASSERT_EQ(damaged_entry.kind, TileKind::kProcedural);
    ASSERT_EQ(intact_entry.kind, TileKind::kProcedural);
    ASSERT_NE(damaged_entry.offset_bytes, intact_entry.offset_bytes);
    EXPECT_TRUE((*archive)->verify().ok());
  }
  flipByte(o.output, damaged_entry.offset_bytes + 20);
  auto archive = Archive::openFile(o.output);
  ASSERT_TRUE(archive) << archive.error().message;
  auto bad = (*archive)->readTile(damaged);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(bad.error().message.find("tile (0,0,0)"), std::string::npos) << bad.error().message;
  auto good = (*archive)->readTile(intact);
  ASSERT_TRUE(good) << good.error().message;
  Image expected;
  ASSERT_TRUE(compositeTileReference(*reference_set_, {0, 3, 2, 128, 1, kWidth, kHeight},
                                     instances_, expected));
  EXPECT_EQ(good->texels, expected.texels);
  for (bool decode : {true, false}) {
    VerifyReport report = (*archive)->verify(decode);
    EXPECT_FALSE(report.ok());
    ASSERT_FALSE(report.faults.empty());
    EXPECT_NE(report.faults[0].find("tile (0,0,0)"), std::string::npos) << report.faults[0];
  }
}

// Item 3: an instance naming a brush the archive lacks fails the tile (decodeTile, verify's
// fast mode through checkPage), and a damaged brush image fails every procedural tile, naming
// the brush, while open() and the baked tiles are unaffected.
TEST_F(ProceduralBuildTest, ArchiveFailsProceduralTilesWithoutTheirBrush) {
  ProceduralBuildOptions o = options("mixed.tess");
  auto report = buildProceduralArchive(o);
  ASSERT_TRUE(report) << report.error().message;
  ASSERT_GT(report->tiles_procedural, 0u);
  ASSERT_GT(report->tiles_baked, 0u);
  auto archive = Archive::openFile(o.output);
  ASSERT_TRUE(archive) << archive.error().message;
  const ImageInfo& info = (*archive)->images()[0];
  std::vector<TileId> procedural, baked;
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        auto entry = (*archive)->tileEntry({0, level, x, y});
        ASSERT_TRUE(entry);
        if (entry->kind == TileKind::kProcedural) procedural.push_back({0, level, x, y});
        if (entry->kind == TileKind::kEncoded) baked.push_back({0, level, x, y});
      }
  ASSERT_FALSE(procedural.empty());
  ASSERT_FALSE(baked.empty());
  const TileId id = procedural[0];
  const TileEntry entry = *(*archive)->tileEntry(id);
  auto page = (*archive)->readPayload(id, entry);
  ASSERT_TRUE(page) << page.error().message;
  auto instances = detail::decodeInstancePage(*page, 1000, "page");
  ASSERT_TRUE(instances && !instances->empty());
  (*instances)[0].brush = 999;
  const std::vector<uint8_t> forged_page = detail::encodeInstancePage(*instances);
  TileEntry forged = entry;
  forged.length_bytes = uint32_t(forged_page.size());
  forged.checksum = detail::checksum64(forged_page);
  auto no_brush = (*archive)->decodeTile(id, forged, forged_page);
  ASSERT_FALSE(no_brush);
  EXPECT_EQ(no_brush.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(no_brush.error().message.find("brush 999"), std::string::npos)
      << no_brush.error().message;
  auto tiles = (*archive)->procedural();
  ASSERT_TRUE(tiles);
  auto checked = (*tiles)->checkPage(**archive, id, forged, forged_page);
  ASSERT_FALSE(checked);
  EXPECT_NE(checked.error().message.find("brush 999"), std::string::npos);

  // A damaged brush image: the archive still opens and serves its baked tiles.
  const detail::ProceduralDirectory directory = proceduralDirectoryOf(o.output);
  flipByte(o.output, directory.images[0].block.offset_bytes + 3);
  auto damaged = Archive::openFile(o.output);
  ASSERT_TRUE(damaged) << damaged.error().message;
  EXPECT_TRUE((*damaged)->readTile(baked[0]));
  auto failed = (*damaged)->readTile(procedural[0]);
  ASSERT_FALSE(failed);
  EXPECT_EQ(failed.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(failed.error().message.find("brush 0 image 0"), std::string::npos)
      << failed.error().message;
  EXPECT_FALSE((*damaged)->verify(false).ok());
}

// Item 5: masked brushes over a baked base layer (--base, a height image): every tile read
// through Archive::readTile equals the brute-force compositor with the same layer.
TEST_F(ProceduralBuildTest, MixedArchiveWithBaseEqualsTheReference) {
  const std::string database = (dir_ / "masked.sqlite").string();
  const std::string base = (dir_ / "dem.png").string();
  const Image height = testing::heightLayer(350, 250);
  ASSERT_TRUE(writePng(height, base));
  std::vector<Brush> brushes = testing::testBrushes();
  std::vector<BrushInstance> instances =
      testing::randomInstances(500, kWidth, kHeight, uint32_t(brushes.size()), 29);
  {
    auto db = openSqliteBrushDatabase(database, true);
    ASSERT_TRUE(db) << db.error().message;
    ASSERT_TRUE((*db)->setTextureExtent({kWidth, kHeight}));
    for (const Brush& brush : brushes) ASSERT_TRUE((*db)->addBrush(brush));
    auto ids = (*db)->addInstances(instances);
    ASSERT_TRUE(ids) << ids.error().message;
    for (size_t i = 0; i < instances.size(); ++i) instances[i].id = (*ids)[i];
  }
  std::sort(instances.begin(), instances.end(), drawsBefore);
  auto set = BrushSet::prepare(brushes, {height}, kWidth, kHeight);
  ASSERT_TRUE(set) << set.error().message;
  ProceduralBuildOptions o = options("based.tess");
  o.database = database;
  o.base = base;
  auto report = buildProceduralArchive(o);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_GT(report->tiles_procedural, 0u);
  auto archive = Archive::openFile(o.output);
  ASSERT_TRUE(archive) << archive.error().message;
  const ImageInfo& info = (*archive)->images()[0];
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        auto got = (*archive)->readTile({0, level, x, y});
        ASSERT_TRUE(got) << got.error().message;
        Image expected;
        ASSERT_TRUE(compositeTileReference(**set, {level, x, y, 128, 1, kWidth, kHeight}, instances,
                                           expected));
        ASSERT_EQ(got->texels, expected.texels)
            << "tile " << level << "," << x << "," << y << " "
            << tileKindName((*archive)->tileEntry({0, level, x, y})->kind);
      }
  // And a region across tiles of both kinds, as renderers and extract read it.
  auto region = (*archive)->readRegionRgba(0, 0, {100, 90, 300, 200});
  ASSERT_TRUE(region) << region.error().message;
  EXPECT_TRUE((*archive)->verify().ok());
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
