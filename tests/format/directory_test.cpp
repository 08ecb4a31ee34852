// Page indexes and directory pages: golden bytes written by hand from docs/format.md, round
// trips, page geometry at the grid's edges, and every entry field out of bounds.
#include "format/directory.h"

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

// 1000 x 600 px, 64 px tiles: level 0 is 16 x 10 tiles; 2^3 = 8-tile pages make 2 x 2 pages,
// the right column 8 wide and the bottom row 2 high.
ImageInfo pagedInfo(uint32_t channels = 3) {
  ImageInfo info;
  info.width_px = 1000;
  info.height_px = 600;
  info.channels = channels;
  info.tile_size_px = 64;
  info.border_px = 0;
  info.page_tiles_log2 = 3;
  info.level_count = levelCountFor(1000, 600, 64);
  return info;
}

FileHeader pageHeader() {
  FileHeader header;
  header.file_bytes = 1 << 20;
  header.image_count = 1;
  return header;
}

std::vector<TileEntry> goldenEntries() {
  TileEntry encoded;
  encoded.kind = TileKind::kEncoded;
  encoded.codec = Codec::kZstd;
  encoded.offset_bytes = 0x4000;
  encoded.length_bytes = 0x0102;
  encoded.checksum = 0x0807060504030201ull;
  TileEntry uniform;
  uniform.kind = TileKind::kUniform;
  uniform.uniform_rgba = 0x00C0B0A0;  // RGB: A0 B0 C0
  TileEntry empty;
  return {encoded, uniform, empty};
}

std::vector<uint8_t> goldenEntryBytes() {
  return {
      // encoded: offset 0x4000, length 0x102, kind 2, codec 1 (zstd), reserved, checksum
      0x00, 0x40, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x01, 0x00, 0x00,  //
      0x02, 0x01, 0x00, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08,  //
      // uniform: colour in the low 4 bytes, kind 1, everything else zero
      0xA0, 0xB0, 0xC0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  //
      0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  //
      // empty: all zero
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  //
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  //
  };
}

void expectSameEntry(const TileEntry& a, const TileEntry& b) {
  EXPECT_EQ(a.kind, b.kind);
  EXPECT_EQ(a.codec, b.codec);
  EXPECT_EQ(a.offset_bytes, b.offset_bytes);
  EXPECT_EQ(a.length_bytes, b.length_bytes);
  EXPECT_EQ(a.checksum, b.checksum);
  EXPECT_EQ(a.uniform_rgba, b.uniform_rgba);
}

TEST(TileEntries, EncodeMatchesGoldenBytes) {
  EXPECT_EQ(encodeTileEntries(goldenEntries()), goldenEntryBytes());
}

TEST(TileEntries, DecodeOfGoldenBytesGivesEveryField) {
  auto decoded = decodeTileEntries(goldenEntryBytes(), pagedInfo(3), pageHeader(), "p");
  ASSERT_TRUE(decoded) << decoded.error().message;
  ASSERT_EQ(decoded->size(), 3u);
  for (size_t i = 0; i < 3; ++i) expectSameEntry((*decoded)[i], goldenEntries()[i]);
}

TEST(TileEntries, DecodeInvertsEncodeForEveryCodecAndKind) {
  std::vector<TileEntry> entries;
  for (uint8_t codec = 0; codec <= uint8_t(Codec::kBc7); ++codec) {
    TileEntry entry;
    entry.kind = TileKind::kEncoded;
    entry.codec = Codec(codec);
    entry.offset_bytes = 16384 + codec * 1000;
    entry.length_bytes = 1 + codec;
    entry.checksum = ~uint64_t(codec);
    entries.push_back(entry);
  }
  TileEntry uniform;
  uniform.kind = TileKind::kUniform;
  uniform.uniform_rgba = 0xFFFFFFFF;
  entries.push_back(uniform);
  entries.push_back(TileEntry{});
  auto decoded = decodeTileEntries(encodeTileEntries(entries), pagedInfo(4), pageHeader(), "p");
  ASSERT_TRUE(decoded) << decoded.error().message;
  ASSERT_EQ(decoded->size(), entries.size());
  for (size_t i = 0; i < entries.size(); ++i) expectSameEntry((*decoded)[i], entries[i]);
}

TEST(TileEntries, DecodeRejectsPartialEntries) {
  const std::vector<uint8_t> golden = goldenEntryBytes();
  for (size_t length = 0; length <= golden.size(); ++length) {
    std::vector<uint8_t> prefix(golden.begin(), golden.begin() + length);  // fresh allocation
    auto decoded = decodeTileEntries(prefix, pagedInfo(3), pageHeader(), "p");
    if (length % kTileEntryBytes == 0) {
      ASSERT_TRUE(decoded) << length;
      EXPECT_EQ(decoded->size(), length / kTileEntryBytes);
    } else {
      ASSERT_FALSE(decoded) << length;
      EXPECT_EQ(decoded.error().code, ErrorCode::kCorrupt);
    }
  }
}

struct BadEntry {
  const char* what;
  size_t entry;   // which golden entry to edit
  size_t offset;  // byte within it
  uint8_t value;
  ErrorCode code = ErrorCode::kCorrupt;
};

TEST(TileEntries, DecodeRejectsEveryFieldOutOfBounds) {
  const BadEntry cases[] = {
      {"unknown kind", 0, 12, 4},
      {"kind 255", 0, 12, 255},
      {"procedural kind", 0, 12, 3, ErrorCode::kUnsupported},
      {"unknown codec", 0, 13, 10},
      {"reserved low byte", 0, 14, 1},
      {"reserved high byte", 0, 15, 1},
      {"payload inside the header region", 0, 1, 0x3F},
      {"payload past the end", 0, 2, 0x10},
      {"zero length", 0, 9, 0x00},
      {"length over the bound", 0, 11, 0x01},
      {"uniform with an offset", 1, 4, 1},
      {"uniform with a length", 1, 8, 1},
      {"uniform with a checksum", 1, 23, 1},
      {"uniform with a codec", 1, 13, 1},
      {"uniform alpha in an RGB image", 1, 3, 0xFF},
      {"uniform reserved", 1, 14, 1},
      {"empty with an offset", 2, 0, 1},
      {"empty with a length", 2, 8, 1},
      {"empty with a codec", 2, 13, 1},
      {"empty with a checksum", 2, 16, 1},
  };
  for (const BadEntry& c : cases) {
    std::vector<uint8_t> bytes = goldenEntryBytes();
    if (std::string(c.what) == "zero length") bytes[8] = 0;
    bytes[c.entry * kTileEntryBytes + c.offset] = c.value;
    auto decoded = decodeTileEntries(bytes, pagedInfo(3), pageHeader(), "scan.tess: page");
    ASSERT_FALSE(decoded) << c.what;
    EXPECT_EQ(decoded.error().code, c.code) << c.what;
    EXPECT_NE(decoded.error().message.find("entry " + std::to_string(c.entry)), std::string::npos)
        << c.what << ": " << decoded.error().message;
  }
}

TEST(TileEntries, DecodeAcceptsAPayloadEndingExactlyAtTheFileEnd) {
  std::vector<TileEntry> entries = goldenEntries();
  FileHeader header = pageHeader();
  header.file_bytes = entries[0].offset_bytes + entries[0].length_bytes;
  EXPECT_TRUE(decodeTileEntries(encodeTileEntries(entries), pagedInfo(3), header, "p"));
  header.file_bytes -= 1;
  EXPECT_FALSE(decodeTileEntries(encodeTileEntries(entries), pagedInfo(3), header, "p"));
}

TEST(TileEntries, DecodeAcceptsAnEntryReservedFieldInANewerMinor) {
  std::vector<uint8_t> bytes = goldenEntryBytes();
  bytes[14] = 1;
  FileHeader header = pageHeader();
  header.version_minor = kFormatVersionMinor + 1;
  EXPECT_TRUE(decodeTileEntries(bytes, pagedInfo(3), header, "p"));
}

TEST(TileEntries, UniformColourMayUseEveryChannelOfAnRgbaImage) {
  std::vector<uint8_t> bytes = goldenEntryBytes();
  bytes[kTileEntryBytes + 3] = 0xFF;
  auto decoded = decodeTileEntries(bytes, pagedInfo(4), pageHeader(), "p");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ((*decoded)[1].uniform_rgba, 0xFFC0B0A0u);
  // A gray image may use only the first byte.
  bytes[kTileEntryBytes + 3] = 0;
  EXPECT_FALSE(decodeTileEntries(bytes, pagedInfo(1), pageHeader(), "p"));
}

ImageInfo wideInfo(SampleType type) {
  ImageInfo info = pagedInfo(3);
  info.sample_type = type;
  return info;
}

TEST(TileEntries, WideImagesHaveNoUniformEntries) {
  // Golden entry 1 is uniform: fine for u8, corrupt for u16 and f32.
  for (SampleType type : {SampleType::kU16, SampleType::kF32}) {
    auto decoded = decodeTileEntries(goldenEntryBytes(), wideInfo(type), pageHeader(), "w.tess");
    ASSERT_FALSE(decoded) << sampleTypeName(type);
    EXPECT_EQ(decoded.error().code, ErrorCode::kCorrupt);
    EXPECT_NE(decoded.error().message.find("uniform entry 1"), std::string::npos)
        << decoded.error().message;
  }
}

TEST(TileEntries, EntriesMustNameACodecThatHoldsTheSampleType) {
  struct Case {
    SampleType type;
    Codec codec;
    bool accepted;
  };
  const Case cases[] = {
      {SampleType::kU16, Codec::kZdelta, true}, {SampleType::kU16, Codec::kPng, true},
      {SampleType::kU16, Codec::kJpeg, false},  {SampleType::kU16, Codec::kPtm, false},
      {SampleType::kF32, Codec::kZstd, true},   {SampleType::kF32, Codec::kPng, false},
      {SampleType::kF32, Codec::kWebp, false},  {SampleType::kU8, Codec::kZdelta, true},
  };
  for (const Case& c : cases) {
    std::vector<uint8_t> bytes = goldenEntryBytes();
    bytes.resize(kTileEntryBytes);  // the encoded entry alone
    bytes[13] = uint8_t(c.codec);
    auto decoded = decodeTileEntries(bytes, wideInfo(c.type), pageHeader(), "w.tess");
    EXPECT_EQ(decoded.has_value(), c.accepted)
        << codecName(c.codec) << " " << sampleTypeName(c.type);
    if (!decoded) {
      EXPECT_NE(decoded.error().message.find("cannot hold"), std::string::npos);
    }
  }
}

// ---- Page index ------------------------------------------------------------------------------

std::vector<PageRef> goldenPageRefs() {
  return {{0x12345, 8 * 8 * 24, 0xF1E2D3C4B5A69788ull},
          {0, 0, 0},
          {0x23456, 8 * 2 * 24, 0x1ull},
          {0x34567, 8 * 2 * 24, 0x8000000000000000ull}};
}

std::vector<uint8_t> goldenPageIndexBytes() {
  return {
      0x45, 0x23, 0x01, 0,    0,    0,    0,    0,  // page (0,0): offset
      0x00, 0x06, 0x00, 0,    0,    0,    0,    0,  // length 1536 = 64 entries
      0x88, 0x97, 0xA6, 0xB5, 0xC4, 0xD3, 0xE2, 0xF1,
      0,    0,    0,    0,    0,    0,    0,    0,     // page (1,0): every tile empty
      0,    0,    0,    0,    0,    0,    0,    0,     //
      0,    0,    0,    0,    0,    0,    0,    0,     //
      0x56, 0x34, 0x02, 0,    0,    0,    0,    0,     // page (0,1): 8 x 2 tiles
      0x80, 0x01, 0x00, 0,    0,    0,    0,    0,     // 384
      0x01, 0,    0,    0,    0,    0,    0,    0,     //
      0x67, 0x45, 0x03, 0,    0,    0,    0,    0,     // page (1,1)
      0x80, 0x01, 0x00, 0,    0,    0,    0,    0,     //
      0,    0,    0,    0,    0,    0,    0,    0x80,  //
  };
}

TEST(PageIndex, EncodeMatchesGoldenBytes) {
  EXPECT_EQ(encodePageIndex(goldenPageRefs()), goldenPageIndexBytes());
}

TEST(PageIndex, DecodeOfGoldenBytesGivesEveryRef) {
  auto decoded = decodePageIndex(goldenPageIndexBytes(), pagedInfo(), 0, 1 << 20, "idx");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(*decoded, goldenPageRefs());
}

TEST(PageIndex, DecodeRejectsEveryTruncationAndTrailingBytes) {
  const std::vector<uint8_t> golden = goldenPageIndexBytes();
  for (size_t length = 0; length < golden.size(); ++length) {
    std::vector<uint8_t> prefix(golden.begin(), golden.begin() + length);
    auto decoded = decodePageIndex(prefix, pagedInfo(), 0, 1 << 20, "idx");
    ASSERT_FALSE(decoded) << length;
    EXPECT_EQ(decoded.error().code, ErrorCode::kCorrupt);
  }
  std::vector<uint8_t> longer = golden;
  longer.resize(golden.size() + kPageRefBytes);
  EXPECT_FALSE(decodePageIndex(longer, pagedInfo(), 0, 1 << 20, "idx"));
}

TEST(PageIndex, DecodeRejectsAPageWhoseLengthDisagreesWithItsTiles) {
  std::vector<PageRef> refs = goldenPageRefs();
  refs[2].length_bytes = 8 * 8 * 24;  // a bottom-row page holds only 2 rows
  auto decoded = decodePageIndex(encodePageIndex(refs), pagedInfo(), 0, 1 << 20, "idx");
  ASSERT_FALSE(decoded);
  EXPECT_NE(decoded.error().message.find("page 2"), std::string::npos) << decoded.error().message;
}

TEST(PageIndex, DecodeRejectsAnEmptyPageWithAnOffsetOrChecksum) {
  for (int field = 0; field < 2; ++field) {
    std::vector<PageRef> refs = goldenPageRefs();
    (field == 0 ? refs[1].offset_bytes : refs[1].checksum) = 1;
    EXPECT_FALSE(decodePageIndex(encodePageIndex(refs), pagedInfo(), 0, 1 << 20, "idx"));
  }
}

TEST(PageIndex, DecodeRejectsPagesOutsideTheFile) {
  for (uint64_t offset : {0ull, 127ull, (1ull << 20) - 383, ~0ull - 100}) {
    std::vector<PageRef> refs = goldenPageRefs();
    refs[3].offset_bytes = offset;
    EXPECT_FALSE(decodePageIndex(encodePageIndex(refs), pagedInfo(), 0, 1 << 20, "idx")) << offset;
  }
}

TEST(PageIndex, DecodePageRefFindsOneRefAtItsPosition) {
  std::vector<uint8_t> bytes = goldenPageIndexBytes();
  auto ref =
      decodePageRef(std::span(bytes).subspan(3 * kPageRefBytes), pagedInfo(), 0, 3, 1 << 20, "idx");
  ASSERT_TRUE(ref) << ref.error().message;
  EXPECT_EQ(*ref, goldenPageRefs()[3]);
}

TEST(PageGeometry, ClipsPagesAtTheRightAndBottomOfTheGrid) {
  ImageInfo info = pagedInfo();
  ASSERT_EQ(pagesX(info, 0), 2u);
  ASSERT_EQ(pagesY(info, 0), 2u);
  PageGeometry corner = pageGeometry(info, 0, 1, 1);
  EXPECT_EQ(corner.first_tile_x, 8u);
  EXPECT_EQ(corner.first_tile_y, 8u);
  EXPECT_EQ(corner.columns, 8u);
  EXPECT_EQ(corner.rows, 2u);
  EXPECT_EQ(corner.bytes(), 8u * 2 * 24);
  // Level 2 is 250 x 150 px: 4 x 3 tiles in one page.
  EXPECT_EQ(pagesX(info, 2), 1u);
  PageGeometry coarse = pageGeometry(info, 2, 0, 0);
  EXPECT_EQ(coarse.columns, 4u);
  EXPECT_EQ(coarse.rows, 3u);
}

TEST(PageGeometry, PagesTileTheGridExactlyForEveryPageSize) {
  ImageInfo info = pagedInfo();
  for (uint32_t log2 = 3; log2 <= 8; ++log2) {
    info.page_tiles_log2 = log2;
    for (uint32_t level = 0; level < info.level_count; ++level) {
      std::vector<int> covered(size_t(info.tilesX(level)) * info.tilesY(level), 0);
      for (uint32_t py = 0; py < pagesY(info, level); ++py) {
        for (uint32_t px = 0; px < pagesX(info, level); ++px) {
          PageGeometry page = pageGeometry(info, level, px, py);
          ASSERT_GE(page.columns, 1u);
          ASSERT_GE(page.rows, 1u);
          for (uint32_t y = 0; y < page.rows; ++y)
            for (uint32_t x = 0; x < page.columns; ++x)
              ++covered[size_t(page.first_tile_y + y) * info.tilesX(level) + page.first_tile_x + x];
        }
      }
      for (int count : covered) ASSERT_EQ(count, 1) << "log2 " << log2 << " level " << level;
    }
  }
}

TEST(MaxPayloadBytes, BoundsAStoredTileWithRoomForCodecOverhead) {
  ImageInfo info = pagedInfo(4);
  info.border_px = 4;
  EXPECT_EQ(maxPayloadBytes(info), uint64_t(72) * 72 * 4 * 2 + 65536);
}

}  // namespace
}  // namespace tessera::detail
