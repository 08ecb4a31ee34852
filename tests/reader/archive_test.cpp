// Archive::open and readTile on a small real archive: what it reports, and that truncation and
// corruption anywhere in the header, directory or payloads are rejected without a crash.
#include <tessera/archive.h>

#include <algorithm>
#include <set>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "format/checksum.h"
#include "format/directory.h"
#include "format/header.h"
#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera {
namespace {

using test::BuiltArchive;

// A few tiles on two levels: 100 x 90 px in 64 px tiles is 2 x 2 tiles, then 50 x 45 in one.
struct SmallArchive {
  Image image = test::makePatternImage(100, 90, 3, 5);
  BuiltArchive built;
  SmallArchive() {
    BuildOptions options;
    options.tile_size_px = 64;
    options.border_px = 1;
    options.codec = Codec::kZstd;
    options.threads = 2;
    built = test::buildFromImage(image, options, test::testTempDir(), "small.tess");
  }
};

std::shared_ptr<Archive> openBytes(std::vector<uint8_t> bytes, std::string name = "small.tess") {
  auto archive = Archive::open(makeMemorySource(std::move(bytes), std::move(name)));
  EXPECT_TRUE(archive) << archive.error().message;
  return archive ? *archive : nullptr;
}

// Offsets of every block the small archive's directory uses, found with the format decoders.
struct Layout {
  detail::FileHeader header;
  uint64_t region_used_end = 0;        ///< end of the last block inside the header region
  std::vector<detail::PageRef> pages;  ///< every non-empty directory page
};

Layout parseLayout(const std::vector<uint8_t>& bytes) {
  Layout layout;
  auto header = detail::decodeHeader(bytes, "x");
  EXPECT_TRUE(header);
  layout.header = *header;
  auto root = detail::decodeRootDirectory(
      std::span(bytes).subspan(header->root.offset_bytes, header->root.length_bytes), *header, "x");
  EXPECT_TRUE(root);
  auto note = [&](const detail::BlockRef& block) {
    if (block.length_bytes && block.offset_bytes < detail::kHeaderRegionBytes)
      layout.region_used_end =
          std::max(layout.region_used_end, block.offset_bytes + block.length_bytes);
  };
  note(header->root);
  note(header->metadata);
  for (const detail::ImageRecord& record : *root) {
    for (uint32_t level = 0; level < record.levels.size(); ++level) {
      const detail::BlockRef& index = record.levels[level].page_index;
      note(index);
      if (!index.length_bytes) continue;
      auto refs =
          detail::decodePageIndex(std::span(bytes).subspan(index.offset_bytes, index.length_bytes),
                                  record.info, level, header->file_bytes, "x");
      EXPECT_TRUE(refs);
      for (const detail::PageRef& ref : *refs)
        if (ref.length_bytes) layout.pages.push_back(ref);
    }
  }
  return layout;
}

// Opens and verifies; true when either reports the damage.
bool rejected(std::vector<uint8_t> bytes, std::string* why) {
  auto archive = Archive::open(makeMemorySource(std::move(bytes), "bad.tess"));
  if (!archive) {
    *why = archive.error().message;
    return true;
  }
  VerifyReport report = (*archive)->verify();
  if (!report.ok()) *why = report.faults.front();
  return !report.ok();
}

TEST(Archive, OpenReportsTheImageGeometryAndMetadata) {
  SmallArchive small;
  ASSERT_FALSE(small.built.bytes.empty());
  auto archive = openBytes(small.built.bytes);
  ASSERT_TRUE(archive);
  EXPECT_EQ(archive->name(), "small.tess");
  EXPECT_EQ(archive->fileBytes(), small.built.bytes.size());
  ASSERT_EQ(archive->images().size(), 1u);
  const ImageInfo& info = archive->images()[0];
  EXPECT_EQ(info.width_px, 100u);
  EXPECT_EQ(info.height_px, 90u);
  EXPECT_EQ(info.channels, 3u);
  EXPECT_EQ(info.tile_size_px, 64u);
  EXPECT_EQ(info.border_px, 1u);
  EXPECT_EQ(info.level_count, 2u);
  EXPECT_EQ(info.default_codec, Codec::kZstd);
  EXPECT_EQ(info.name, "source.png");
  ASSERT_TRUE(nlohmann::json::parse(archive->metadataJson()).is_object());
  EXPECT_EQ(nlohmann::json::parse(archive->metadataJson()).value("format", ""), "tessera");
  EXPECT_EQ(nlohmann::json::parse(archive->metadataJson())["build"].value("tile_size", 0), 64);
}

TEST(Archive, OpenFileReadsTheSameArchive) {
  SmallArchive small;
  auto archive = Archive::openFile(small.built.path);
  ASSERT_TRUE(archive) << archive.error().message;
  EXPECT_EQ((*archive)->name(), small.built.path);
  EXPECT_TRUE((*archive)->verify().ok());
}

TEST(Archive, OpenFileOfAMissingPathIsNotFound) {
  std::string path = test::testTempDir() + "missing.tess";
  auto archive = Archive::openFile(path);
  ASSERT_FALSE(archive);
  EXPECT_EQ(archive.error().code, ErrorCode::kNotFound);
  EXPECT_NE(archive.error().message.find(path), std::string::npos);
}

TEST(Archive, OpenRejectsAnEmptySource) {
  auto archive = Archive::open(makeMemorySource({}, "empty.tess"));
  ASSERT_FALSE(archive);
  EXPECT_EQ(archive.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(archive.error().message.find("empty.tess"), std::string::npos);
}

// Bytes past file_bytes are the uncommitted tail of an interrupted update (docs/format.md,
// "Appended versions"): the committed version opens, whole.
TEST(Archive, OpenIgnoresAnUncommittedTail) {
  SmallArchive small;
  std::vector<uint8_t> bytes = small.built.bytes;
  bytes.insert(bytes.end(), 3000, 0xEE);
  auto archive = Archive::open(makeMemorySource(bytes, "long.tess"));
  ASSERT_TRUE(archive) << archive.error().message;
  EXPECT_EQ((*archive)->fileBytes(), small.built.bytes.size());
  EXPECT_TRUE((*archive)->verify().ok());
}

// A torn header write: the header copy, the file's last 128 bytes, stands in for it only when
// it describes exactly this file.
TEST(Archive, ATornHeaderIsReadFromTheCopyAtTheEndOnlyWhenTheCopyFitsTheFile) {
  SmallArchive small;
  std::vector<uint8_t> bytes = small.built.bytes;
  auto header = detail::decodeHeader(bytes, "x");
  ASSERT_TRUE(header);
  detail::FileHeader with_copy = *header;
  with_copy.file_bytes = bytes.size() + detail::kHeaderBytes;
  const std::vector<uint8_t> copy = detail::encodeHeader(with_copy);
  bytes.insert(bytes.end(), copy.begin(), copy.end());
  std::copy(copy.begin(), copy.end(), bytes.begin());
  ASSERT_TRUE(Archive::open(makeMemorySource(bytes, "whole.tess")));
  for (size_t i = 40; i < 100; ++i) bytes[i] ^= 0x33;  // torn: checksum fails
  auto recovered = Archive::open(makeMemorySource(bytes, "torn.tess"));
  ASSERT_TRUE(recovered) << recovered.error().message;
  EXPECT_TRUE((*recovered)->verify().ok());
  // The same copy behind a tail does not describe the file: the torn header is reported.
  bytes.push_back(0);
  auto refused = Archive::open(makeMemorySource(bytes, "torn-long.tess"));
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("header checksum mismatch"), std::string::npos);
}

TEST(Archive, ReadTileEqualsTheReferenceOnEveryTile) {
  SmallArchive small;
  auto archive = openBytes(small.built.bytes);
  ASSERT_TRUE(archive);
  test::ReferencePyramid reference(small.image);
  const ImageInfo& info = archive->images()[0];
  for (uint32_t level = 0; level < info.level_count; ++level) {
    for (uint32_t y = 0; y < info.tilesY(level); ++y) {
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        auto tile = archive->readTile({0, level, x, y});
        ASSERT_TRUE(tile) << tile.error().message;
        test::ReferenceTile expected = reference.tile(level, x, y, 64, 1);
        EXPECT_EQ(test::firstDifference(expected.texels, *tile), "")
            << "tile (" << level << "," << x << "," << y << ")";
      }
    }
  }
}

TEST(Archive, TileEntryRejectsAddressesOutsideTheImage) {
  SmallArchive small;
  auto archive = openBytes(small.built.bytes);
  ASSERT_TRUE(archive);
  const TileId outside[] = {{1, 0, 0, 0}, {0, 2, 0, 0}, {0, 0, 2, 0}, {0, 0, 0, 2}, {0, 1, 1, 0}};
  for (const TileId& tile : outside) {
    auto entry = archive->tileEntry(tile);
    ASSERT_FALSE(entry);
    EXPECT_EQ(entry.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(entry.error().message.find("small.tess"), std::string::npos);
    EXPECT_FALSE(archive->readTile(tile));
  }
}

TEST(Archive, DecodeTileExpandsUniformAndEmptyEntries) {
  SmallArchive small;
  auto archive = openBytes(small.built.bytes);
  ASSERT_TRUE(archive);
  TileEntry uniform;
  uniform.kind = TileKind::kUniform;
  uniform.uniform_rgba = 0x00302010;
  auto tile = archive->decodeTile({0, 0, 0, 0}, uniform, {});
  ASSERT_TRUE(tile);
  ASSERT_EQ(tile->width_px, 66u);
  for (size_t i = 0; i < tile->texels.size(); i += 3) {
    ASSERT_EQ(tile->texels[i], 0x10);
    ASSERT_EQ(tile->texels[i + 1], 0x20);
    ASSERT_EQ(tile->texels[i + 2], 0x30);
  }
  auto empty = archive->decodeTile({0, 0, 0, 0}, TileEntry{}, {});
  ASSERT_TRUE(empty);
  EXPECT_TRUE(
      std::all_of(empty->texels.begin(), empty->texels.end(), [](uint8_t v) { return v == 0; }));
}

TEST(Archive, DecodeTileIntoReusesAnyBufferAndWritesEveryTexel) {
  SmallArchive small;
  auto archive = openBytes(small.built.bytes);
  ASSERT_TRUE(archive);
  const ImageInfo& info = archive->images()[0];
  TileEntry uniform;
  uniform.kind = TileKind::kUniform;
  uniform.uniform_rgba = 0x00302010;
  std::vector<std::pair<TileId, TileEntry>> cases = {{{0, 0, 0, 0}, uniform},
                                                     {{0, 0, 0, 0}, TileEntry{}}};
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        TileId id{0, level, x, y};
        auto entry = archive->tileEntry(id);
        ASSERT_TRUE(entry);
        cases.push_back({id, *entry});
      }
  // A buffer of the right size full of another tile's bytes, a smaller one and a larger one.
  const size_t stored = info.storedTileBytes();
  for (size_t garbage_bytes : {stored, stored / 3, stored * 2}) {
    for (const auto& [id, entry] : cases) {
      SCOPED_TRACE(::testing::Message()
                   << "level " << id.level << " x " << id.x << " y " << id.y << " kind "
                   << int(entry.kind) << " buffer " << garbage_bytes);
      std::vector<uint8_t> payload;
      if (entry.kind == TileKind::kEncoded) {
        auto read = archive->readPayload(id, entry);
        ASSERT_TRUE(read);
        payload = std::move(*read);
      }
      auto expected = archive->decodeTile(id, entry, payload);
      ASSERT_TRUE(expected) << expected.error().message;
      Image reused(1, 1, 1);
      reused.texels.assign(garbage_bytes, 0xAB);
      ASSERT_TRUE(archive->decodeTileInto(id, entry, payload, reused));
      EXPECT_EQ(reused.width_px, expected->width_px);
      EXPECT_EQ(reused.height_px, expected->height_px);
      EXPECT_EQ(reused.channels, expected->channels);
      EXPECT_TRUE(reused.texels == expected->texels);
    }
  }
}

TEST(Archive, EveryTruncationIsRejected) {
  SmallArchive small;
  const std::vector<uint8_t>& bytes = small.built.bytes;
  ASSERT_GT(bytes.size(), detail::kHeaderRegionBytes);
  for (size_t length = 0; length < bytes.size(); ++length) {
    std::string why;
    ASSERT_TRUE(rejected(std::vector<uint8_t>(bytes.begin(), bytes.begin() + length), &why))
        << "prefix of " << length << " bytes accepted";
  }
}

TEST(Archive, TruncationWithAResealedFileSizeIsStillRejected) {
  SmallArchive small;
  const std::vector<uint8_t>& bytes = small.built.bytes;
  auto header = detail::decodeHeader(bytes, "x");
  ASSERT_TRUE(header);
  for (size_t length = detail::kHeaderRegionBytes; length < bytes.size(); ++length) {
    std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + length);
    detail::FileHeader lying = *header;
    lying.file_bytes = length;
    std::vector<uint8_t> header_bytes = detail::encodeHeader(lying);
    std::copy(header_bytes.begin(), header_bytes.end(), prefix.begin());
    std::string why;
    ASSERT_TRUE(rejected(std::move(prefix), &why)) << "prefix of " << length << " bytes accepted";
  }
}

TEST(Archive, EveryBitFlipInTheHeaderRegionIsRejected) {
  SmallArchive small;
  const std::vector<uint8_t>& bytes = small.built.bytes;
  Layout layout = parseLayout(bytes);
  ASSERT_GT(layout.region_used_end, detail::kHeaderBytes);
  for (size_t offset = 0; offset < layout.region_used_end; ++offset) {
    for (uint32_t bit = 0; bit < 8; ++bit) {
      std::vector<uint8_t> flipped = bytes;
      test::flipBit(flipped, offset, bit);
      std::string why;
      ASSERT_TRUE(rejected(std::move(flipped), &why))
          << "flip of bit " << bit << " at " << offset << " accepted";
    }
  }
}

TEST(Archive, EveryBitFlipInEveryDirectoryPageIsRejected) {
  SmallArchive small;
  const std::vector<uint8_t>& bytes = small.built.bytes;
  Layout layout = parseLayout(bytes);
  ASSERT_EQ(layout.pages.size(), 2u);  // one page per level
  for (const detail::PageRef& page : layout.pages) {
    for (uint64_t offset = page.offset_bytes; offset < page.offset_bytes + page.length_bytes;
         ++offset) {
      for (uint32_t bit = 0; bit < 8; ++bit) {
        std::vector<uint8_t> flipped = bytes;
        test::flipBit(flipped, offset, bit);
        std::string why;
        ASSERT_TRUE(rejected(std::move(flipped), &why))
            << "flip of bit " << bit << " at " << offset << " accepted";
        EXPECT_NE(why.find("checksum"), std::string::npos) << why;
      }
    }
  }
}

TEST(Archive, AFlippedPayloadByteFailsThatTileOnly) {
  SmallArchive small;
  auto pristine = openBytes(small.built.bytes);
  ASSERT_TRUE(pristine);
  const ImageInfo info = pristine->images()[0];
  std::vector<TileId> encoded;
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x)
        if (pristine->tileEntry({0, level, x, y})->kind == TileKind::kEncoded)
          encoded.push_back({0, level, x, y});
  ASSERT_GE(encoded.size(), 2u);
  for (const TileId& victim : encoded) {
    TileEntry entry = *pristine->tileEntry(victim);
    std::vector<uint8_t> bytes = small.built.bytes;
    bytes[entry.offset_bytes + entry.length_bytes / 2] ^= 0x40;
    auto archive = openBytes(bytes);
    ASSERT_TRUE(archive);
    for (const TileId& tile : encoded) {
      auto read = archive->readTile(tile);
      if (tile == victim) {
        ASSERT_FALSE(read);
        EXPECT_EQ(read.error().code, ErrorCode::kCorrupt);
        std::string name = "tile (" + std::to_string(tile.level) + "," + std::to_string(tile.x) +
                           "," + std::to_string(tile.y) + ")";
        EXPECT_NE(read.error().message.find(name), std::string::npos) << read.error().message;
      } else {
        EXPECT_TRUE(read) << read.error().message;
      }
    }
  }
}

TEST(Archive, ReadsBlocksOutsideTheHeaderRegionThroughTheSource) {
  // A source that counts reads: opening costs one read of the header region, and a tile costs
  // at most a page and a payload read.
  class CountingSource final : public ByteSource {
   public:
    explicit CountingSource(std::shared_ptr<ByteSource> inner) : inner_(std::move(inner)) {}
    uint64_t sizeBytes() const override { return inner_->sizeBytes(); }
    const std::string& name() const override { return inner_->name(); }
    Result<void> read(uint64_t offset, std::span<uint8_t> out) const override {
      ++reads;
      return inner_->read(offset, out);
    }
    mutable std::atomic<int> reads{0};

   private:
    std::shared_ptr<ByteSource> inner_;
  };
  SmallArchive small;
  auto source = std::make_shared<CountingSource>(makeMemorySource(small.built.bytes, "c.tess"));
  auto archive = Archive::open(source);
  ASSERT_TRUE(archive);
  EXPECT_EQ(source->reads.load(), 1);
  ASSERT_TRUE((*archive)->readTile({0, 0, 1, 1}));
  EXPECT_LE(source->reads.load(), 3);
  int after_first = source->reads.load();
  ASSERT_TRUE((*archive)->readTile({0, 0, 0, 1}));
  EXPECT_LE(source->reads.load(), after_first + 1);  // the page is cached
}

}  // namespace
}  // namespace tessera
