// Archive::verify: a sound archive passes with exact counts; each kind of damage is reported
// with the object it concerns, including damage that every checksum still vouches for.
#include <tessera/archive.h>

#include <gtest/gtest.h>

#include "format/checksum.h"
#include "format/directory.h"
#include "format/header.h"
#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera {
namespace {

// 400 x 260 RGBA in 64 px tiles: level 0 is 7 x 5 tiles with a flat block (uniform tiles) and
// a transparent block (empty tiles), then 4 x 3 tiles, then 2 x 2, then one.
test::BuiltArchive buildSample() {
  BuildOptions options;
  options.tile_size_px = 64;
  options.codec = Codec::kLz4;
  options.threads = 2;
  options.page_tiles_log2 = 3;
  return test::buildFromImage(test::makePatternImage(400, 260, 4, 9), options, test::testTempDir());
}

// Edits directory entries of an archive in memory and re-seals every checksum above them
// (page, page index, root directory, header), so only verify's deeper checks can object.
class ArchiveEditor {
 public:
  explicit ArchiveEditor(std::vector<uint8_t> bytes) : bytes_(std::move(bytes)) {
    header_ = *detail::decodeHeader(bytes_, "x");
    records_ = *detail::decodeRootDirectory(
        std::span(bytes_).subspan(header_.root.offset_bytes, header_.root.length_bytes), header_,
        "x");
  }

  const ImageInfo& info() const { return records_[0].info; }

  /// Where tile (level, x, y)'s page lives and the entry's index in it.
  struct Slot {
    uint32_t page_index;
    detail::PageRef ref;
    size_t entry;
    detail::PageGeometry geometry;
  };
  Slot slot(uint32_t level, uint32_t x, uint32_t y) const {
    const ImageInfo& image = info();
    uint32_t side = 1u << image.page_tiles_log2;
    uint32_t px = x / side, py = y / side;
    Slot s;
    s.page_index = py * detail::pagesX(image, level) + px;
    s.geometry = detail::pageGeometry(image, level, px, py);
    s.entry =
        size_t(y - s.geometry.first_tile_y) * s.geometry.columns + (x - s.geometry.first_tile_x);
    s.ref = pageRefs(level)[s.page_index];
    return s;
  }

  std::vector<detail::PageRef> pageRefs(uint32_t level) const {
    const detail::BlockRef& index = records_[0].levels[level].page_index;
    return *detail::decodePageIndex(
        std::span(bytes_).subspan(index.offset_bytes, index.length_bytes), info(), level,
        header_.file_bytes, "x");
  }

  TileEntry entry(uint32_t level, uint32_t x, uint32_t y) const {
    Slot s = slot(level, x, y);
    auto entries = *detail::decodeTileEntries(
        std::span(bytes_).subspan(s.ref.offset_bytes, s.ref.length_bytes), info(), header_, "x");
    return entries[s.entry];
  }

  void setEntry(uint32_t level, uint32_t x, uint32_t y, const TileEntry& entry) {
    Slot s = slot(level, x, y);
    auto entries = *detail::decodeTileEntries(
        std::span(bytes_).subspan(s.ref.offset_bytes, s.ref.length_bytes), info(), header_, "x");
    entries[s.entry] = entry;
    std::vector<uint8_t> page = detail::encodeTileEntries(entries);
    std::copy(page.begin(), page.end(), bytes_.begin() + s.ref.offset_bytes);
    std::vector<detail::PageRef> refs = pageRefs(level);
    refs[s.page_index].checksum = detail::checksum64(page);
    setPageIndex(level, refs);
  }

  void setLevelPayloadBytes(uint32_t level, uint64_t bytes) {
    records_[0].levels[level].payload_bytes = bytes;
    resealRoot();
  }

  std::vector<uint8_t>& bytes() { return bytes_; }

 private:
  void setPageIndex(uint32_t level, const std::vector<detail::PageRef>& refs) {
    detail::BlockRef& index = records_[0].levels[level].page_index;
    std::vector<uint8_t> encoded = detail::encodePageIndex(refs);
    std::copy(encoded.begin(), encoded.end(), bytes_.begin() + index.offset_bytes);
    index.checksum = detail::checksum64(encoded);
    resealRoot();
  }

  void resealRoot() {
    std::vector<uint8_t> root = detail::encodeRootDirectory(records_);
    std::copy(root.begin(), root.end(), bytes_.begin() + header_.root.offset_bytes);
    header_.root.checksum = detail::checksum64(root);
    std::vector<uint8_t> header = detail::encodeHeader(header_);
    std::copy(header.begin(), header.end(), bytes_.begin());
  }

  std::vector<uint8_t> bytes_;
  detail::FileHeader header_;
  std::vector<detail::ImageRecord> records_;
};

VerifyReport verifyBytes(std::vector<uint8_t> bytes, bool decode = true) {
  auto archive = Archive::open(makeMemorySource(std::move(bytes), "s.tess"));
  EXPECT_TRUE(archive) << archive.error().message;
  return archive ? (*archive)->verify(decode) : VerifyReport{};
}

bool anyFaultContains(const VerifyReport& report, const std::string& text) {
  for (const std::string& fault : report.faults)
    if (fault.find(text) != std::string::npos) return true;
  return false;
}

TEST(Verify, ASoundArchivePassesWithExactCounts) {
  test::BuiltArchive built = buildSample();
  auto archive = Archive::open(makeMemorySource(built.bytes, "s.tess"));
  ASSERT_TRUE(archive);
  const ImageInfo& info = (*archive)->images()[0];
  uint64_t tiles = 0, encoded = 0, payload = 0, pages = 0;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    pages += uint64_t(detail::pagesX(info, level)) * detail::pagesY(info, level);
    for (uint32_t y = 0; y < info.tilesY(level); ++y) {
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        TileEntry entry = *(*archive)->tileEntry({0, level, x, y});
        ++tiles;
        if (entry.kind == TileKind::kEncoded) ++encoded, payload += entry.length_bytes;
      }
    }
  }
  std::vector<std::pair<uint64_t, uint64_t>> progress;
  VerifyReport report = (*archive)->verify(true, [&](uint64_t done, uint64_t total) {
    progress.push_back({done, total});
  });
  EXPECT_TRUE(report.ok()) << (report.faults.empty() ? "" : report.faults[0]);
  EXPECT_EQ(report.fault_count, 0u);
  EXPECT_EQ(report.tiles_checked, tiles);
  EXPECT_EQ(report.payloads_checked, encoded);
  EXPECT_EQ(report.payload_bytes, payload);
  EXPECT_EQ(report.pages_checked, pages);
  ASSERT_EQ(progress.size(), info.level_count);
  EXPECT_EQ(progress.back().first, progress.back().second);
}

TEST(Verify, APayloadFlipIsReportedNamingTheTileAndItsOffset) {
  test::BuiltArchive built = buildSample();
  ArchiveEditor editor(built.bytes);
  TileEntry entry = editor.entry(0, 3, 1);
  ASSERT_EQ(entry.kind, TileKind::kEncoded);
  editor.bytes()[entry.offset_bytes] ^= 0x01;
  VerifyReport report = verifyBytes(editor.bytes());
  EXPECT_EQ(report.fault_count, 1u);
  ASSERT_EQ(report.faults.size(), 1u);
  EXPECT_NE(report.faults[0].find("s.tess: tile (0,3,1) checksum mismatch at offset " +
                                  std::to_string(entry.offset_bytes)),
            std::string::npos)
      << report.faults[0];
}

TEST(Verify, KeepsGoingAndCountsEveryFault) {
  test::BuiltArchive built = buildSample();
  ArchiveEditor editor(built.bytes);
  int damaged = 0;
  for (uint32_t y = 0; y < editor.info().tilesY(0); ++y) {
    for (uint32_t x = 0; x < editor.info().tilesX(0); ++x) {
      TileEntry entry = editor.entry(0, x, y);
      if (entry.kind != TileKind::kEncoded) continue;
      editor.bytes()[entry.offset_bytes + entry.length_bytes - 1] ^= 0x80;
      ++damaged;
    }
  }
  ASSERT_GE(damaged, 3);
  VerifyReport report = verifyBytes(editor.bytes());
  EXPECT_EQ(report.fault_count, uint64_t(damaged));
}

TEST(Verify, APayloadThatFailsToDecodeIsReportedWhenDecoding) {
  test::BuiltArchive built = buildSample();
  ArchiveEditor editor(built.bytes);
  TileEntry entry = editor.entry(0, 3, 1);
  ASSERT_EQ(entry.kind, TileKind::kEncoded);
  // Damage the payload, then vouch for it with a matching checksum.
  for (uint32_t i = 0; i < entry.length_bytes; ++i) editor.bytes()[entry.offset_bytes + i] = 0xEE;
  entry.checksum =
      detail::checksum64(std::span(editor.bytes()).subspan(entry.offset_bytes, entry.length_bytes));
  editor.setEntry(0, 3, 1, entry);
  EXPECT_TRUE(verifyBytes(editor.bytes(), /*decode=*/false).ok());
  VerifyReport report = verifyBytes(editor.bytes(), /*decode=*/true);
  ASSERT_EQ(report.fault_count, 1u);
  EXPECT_NE(report.faults[0].find("tile (0,3,1)"), std::string::npos) << report.faults[0];
}

TEST(Verify, OverlappingPayloadsAreReported) {
  test::BuiltArchive built = buildSample();
  ArchiveEditor editor(built.bytes);
  TileEntry a = editor.entry(0, 3, 1);
  TileEntry b = editor.entry(0, 4, 1);
  ASSERT_EQ(a.kind, TileKind::kEncoded);
  ASSERT_EQ(b.kind, TileKind::kEncoded);
  editor.setEntry(0, 4, 1, a);  // both tiles now claim a's bytes
  VerifyReport report = verifyBytes(editor.bytes());
  EXPECT_FALSE(report.ok());
  EXPECT_TRUE(anyFaultContains(report, "overlaps")) << report.faults[0];
}

TEST(Verify, ALevelPayloadTotalThatDisagreesWithItsTilesIsReported) {
  test::BuiltArchive built = buildSample();
  ArchiveEditor editor(built.bytes);
  editor.setLevelPayloadBytes(1, 12345);
  VerifyReport report = verifyBytes(editor.bytes());
  ASSERT_EQ(report.fault_count, 1u);
  EXPECT_NE(report.faults[0].find("level 1"), std::string::npos) << report.faults[0];
}

TEST(Verify, ACorruptDirectoryPageIsReportedAndItsTilesSkipped) {
  test::BuiltArchive built = buildSample();
  ArchiveEditor editor(built.bytes);
  ArchiveEditor::Slot slot = editor.slot(0, 0, 0);
  editor.bytes()[slot.ref.offset_bytes + 5] ^= 0x10;
  VerifyReport report = verifyBytes(editor.bytes());
  EXPECT_FALSE(report.ok());
  EXPECT_TRUE(anyFaultContains(report, "page (0,0) checksum mismatch")) << report.faults[0];
}

TEST(Verify, ReportsAtMostTheFaultLimitButCountsAll) {
  // 2048 x 1024 in 64 px tiles with 8-tile pages: 32 x 16 level-0 tiles.
  BuildOptions options;
  options.tile_size_px = 64;
  options.codec = Codec::kRaw;
  options.threads = 2;
  options.page_tiles_log2 = 3;
  test::BuiltArchive built =
      test::buildFromImage(test::makePatternImage(2048, 1024, 1, 3), options, test::testTempDir());
  ArchiveEditor editor(built.bytes);
  uint64_t damaged = 0;
  for (uint32_t y = 0; y < editor.info().tilesY(0); ++y) {
    for (uint32_t x = 0; x < editor.info().tilesX(0); ++x) {
      TileEntry entry = editor.entry(0, x, y);
      if (entry.kind != TileKind::kEncoded) continue;
      editor.bytes()[entry.offset_bytes] ^= 0xFF;
      ++damaged;
    }
  }
  ASSERT_GT(damaged, VerifyReport::kMaxReportedFaults);
  VerifyReport report = verifyBytes(editor.bytes(), false);
  EXPECT_EQ(report.fault_count, damaged);
  EXPECT_EQ(report.faults.size(), VerifyReport::kMaxReportedFaults);
}

}  // namespace
}  // namespace tessera
