// The fixed header and root directory: golden bytes written by hand from the layout in
// docs/format.md, round trips, and every field out of bounds.
#include "format/header.h"

#include <cstring>

#include <gtest/gtest.h>
#include <xxhash.h>

namespace tessera::detail {
namespace {

FileHeader goldenHeader() {
  FileHeader header;
  header.version_major = 1;
  header.version_minor = 0;
  header.header_region_bytes = 16384;
  header.file_bytes = 0xA1B2C3;
  header.image_count = 2;
  header.root = {128, 192, 0x1122334455667788ull};
  header.metadata = {320, 0x123, 0x99AABBCCDDEEFF00ull};
  return header;
}

// Bytes 0..119 of goldenHeader(), little-endian, by hand; 120..127 is the XXH3-64 of them.
std::vector<uint8_t> goldenHeaderBytes() {
  std::vector<uint8_t> bytes = {
      0x89, 'T',  'E',  'S',  'S',  0x0D, 0x0A, 0x1A,  // magic
      0x01, 0x00, 0x00, 0x00,                          // version 1.0
      0x00, 0x40, 0x00, 0x00,                          // header region 16384
      0xC3, 0xB2, 0xA1, 0x00, 0x00, 0x00, 0x00, 0x00,  // file bytes
      0x02, 0x00, 0x00, 0x00,                          // image count
      0x00, 0x00, 0x00, 0x00,                          // flags
      0x80, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // root offset 128
      0xC0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // root length 192
      0x88, 0x77, 0x66, 0x55, 0x44, 0x33, 0x22, 0x11,  // root checksum
      0x40, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // metadata offset 320
      0x23, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // metadata length 291
      0x00, 0xFF, 0xEE, 0xDD, 0xCC, 0xBB, 0xAA, 0x99,  // metadata checksum
  };
  bytes.resize(120, 0);  // reserved 80..119
  uint64_t checksum = XXH3_64bits(bytes.data(), 120);
  for (int i = 0; i < 8; ++i) bytes.push_back(uint8_t(checksum >> (8 * i)));
  return bytes;
}

// Recomputes the checksum after a test edits a field, so the field's own check is reached.
void reseal(std::vector<uint8_t>& bytes) {
  uint64_t checksum = XXH3_64bits(bytes.data(), 120);
  for (int i = 0; i < 8; ++i) bytes[120 + i] = uint8_t(checksum >> (8 * i));
}

void storeLe(std::vector<uint8_t>& bytes, size_t offset, uint64_t value, int width) {
  for (int i = 0; i < width; ++i) bytes[offset + i] = uint8_t(value >> (8 * i));
}

Error decodeError(const std::vector<uint8_t>& bytes) {
  auto decoded = decodeHeader(bytes, "x.tess");
  EXPECT_FALSE(decoded.has_value());
  return decoded ? Error{} : decoded.error();
}

TEST(Header, EncodeMatchesGoldenBytes) {
  EXPECT_EQ(encodeHeader(goldenHeader()), goldenHeaderBytes());
}

TEST(Header, DecodeOfGoldenBytesGivesEveryField) {
  auto decoded = decodeHeader(goldenHeaderBytes(), "x.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(*decoded, goldenHeader());
}

TEST(Header, DecodeInvertsEncodeForEdgeValues) {
  FileHeader header = goldenHeader();
  header.header_region_bytes = kMaxHeaderRegionBytes;
  header.file_bytes = ~0ull;
  header.image_count = kMaxImages;
  header.root = {128, uint64_t(kMaxImages) * 64, ~0ull};
  header.metadata = {};
  auto decoded = decodeHeader(encodeHeader(header), "x.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(*decoded, header);
}

TEST(Header, DecodeAcceptsBytesAfterTheHeader) {
  std::vector<uint8_t> bytes = goldenHeaderBytes();
  bytes.resize(16384, 0xAB);
  EXPECT_TRUE(decodeHeader(bytes, "x.tess"));
}

TEST(Header, DecodeRejectsEveryTruncation) {
  const std::vector<uint8_t> golden = goldenHeaderBytes();
  for (size_t length = 0; length < golden.size(); ++length) {
    std::vector<uint8_t> prefix(golden.begin(), golden.begin() + length);  // fresh allocation
    auto decoded = decodeHeader(prefix, "x.tess");
    ASSERT_FALSE(decoded) << length;
    EXPECT_EQ(decoded.error().code, ErrorCode::kCorrupt) << length;
    EXPECT_NE(decoded.error().message.find("x.tess"), std::string::npos);
  }
}

TEST(Header, DecodeRejectsBadMagic) {
  for (size_t i = 0; i < 8; ++i) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    bytes[i] ^= 0x20;
    Error error = decodeError(bytes);
    EXPECT_EQ(error.code, ErrorCode::kCorrupt);
    EXPECT_NE(error.message.find("bad magic"), std::string::npos) << error.message;
  }
}

TEST(Header, DecodeReportsAnUnwrittenHeader) {
  std::vector<uint8_t> bytes = goldenHeaderBytes();
  std::fill(bytes.begin(), bytes.begin() + 8, 0);
  Error error = decodeError(bytes);
  EXPECT_EQ(error.code, ErrorCode::kCorrupt);
  EXPECT_NE(error.message.find("never written"), std::string::npos) << error.message;
}

TEST(Header, DecodeRejectsANewerMajorAsUnsupported) {
  std::vector<uint8_t> bytes = goldenHeaderBytes();
  storeLe(bytes, 8, 2, 2);
  // No reseal: a newer major may move the checksum, so version is checked first.
  Error error = decodeError(bytes);
  EXPECT_EQ(error.code, ErrorCode::kUnsupported);
  EXPECT_NE(error.message.find("2.0"), std::string::npos) << error.message;
}

TEST(Header, DecodeRejectsMajorZero) {
  std::vector<uint8_t> bytes = goldenHeaderBytes();
  storeLe(bytes, 8, 0, 2);
  reseal(bytes);
  EXPECT_FALSE(decodeHeader(bytes, "x.tess"));
}

TEST(Header, DecodeAcceptsANewerMinorWithReservedFieldsSet) {
  std::vector<uint8_t> bytes = goldenHeaderBytes();
  storeLe(bytes, 10, 3, 2);
  storeLe(bytes, 28, 0xFFFF, 4);
  bytes[100] = 7;
  reseal(bytes);
  auto decoded = decodeHeader(bytes, "x.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(decoded->version_minor, 3);
}

TEST(Header, DecodeRejectsAChecksumMismatch) {
  for (size_t byte : {size_t(12), size_t(40), size_t(119), size_t(120), size_t(127)}) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    bytes[byte] ^= 1;
    Error error = decodeError(bytes);
    EXPECT_EQ(error.code, ErrorCode::kCorrupt);
    EXPECT_NE(error.message.find("checksum"), std::string::npos) << byte << ": " << error.message;
  }
}

TEST(Header, DecodeRejectsNonZeroReservedFields) {
  std::vector<size_t> offsets = {28, 29, 30, 31};
  for (size_t i = 80; i < 120; ++i) offsets.push_back(i);
  for (size_t offset : offsets) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    bytes[offset] = 0x01;
    reseal(bytes);
    Error error = decodeError(bytes);
    EXPECT_EQ(error.code, ErrorCode::kCorrupt) << offset;
    EXPECT_NE(error.message.find("reserved"), std::string::npos) << offset << ": " << error.message;
  }
}

TEST(Header, DecodeRejectsHeaderRegionSizesOutOfBounds) {
  for (uint64_t region : {0ull, 4095ull, 5000ull, 16385ull, 2ull << 20, 0xFFFFFFFFull}) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    storeLe(bytes, 12, region, 4);
    storeLe(bytes, 16, 64ull << 20, 8);
    reseal(bytes);
    Error error = decodeError(bytes);
    EXPECT_EQ(error.code, ErrorCode::kCorrupt) << region;
    EXPECT_NE(error.message.find("header region"), std::string::npos) << error.message;
  }
}

TEST(Header, DecodeAcceptsEveryValidHeaderRegionSize) {
  for (uint64_t region : {4096ull, 8192ull, 16384ull, 1ull << 20}) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    storeLe(bytes, 12, region, 4);
    storeLe(bytes, 16, 2ull << 20, 8);
    reseal(bytes);
    EXPECT_TRUE(decodeHeader(bytes, "x.tess")) << region;
  }
}

TEST(Header, DecodeRejectsAFileSmallerThanTheHeaderRegion) {
  std::vector<uint8_t> bytes = goldenHeaderBytes();
  storeLe(bytes, 16, 16383, 8);
  reseal(bytes);
  EXPECT_EQ(decodeError(bytes).code, ErrorCode::kCorrupt);
}

TEST(Header, DecodeRejectsImageCountsOutOfBounds) {
  for (uint64_t count : {uint64_t(0), uint64_t(kMaxImages) + 1, uint64_t(0xFFFFFFFF)}) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    storeLe(bytes, 24, count, 4);
    reseal(bytes);
    Error error = decodeError(bytes);
    EXPECT_EQ(error.code, ErrorCode::kCorrupt) << count;
    EXPECT_NE(error.message.find("image count"), std::string::npos) << error.message;
  }
}

TEST(Header, DecodeRejectsBlocksOutsideTheFile) {
  struct Case {
    size_t field;  // byte offset of the field to overwrite
    uint64_t value;
  };
  const Case cases[] = {
      {32, 0},               // root inside the fixed header
      {32, 127},             // root overlapping the fixed header
      {32, 0xA1B2C3 - 100},  // root running past the end of the file
      {32, 0xA1B2C4},        // root starting past the end of the file
      {32, ~0ull - 10},      // offset + length wraps around
      {40, ~0ull},           // root length wraps around
      {56, 0xA1B2C3},        // metadata past the end
      {64, 0xA1B2C3},        // metadata longer than the file
      {56, 64},              // metadata inside the fixed header
  };
  for (const Case& c : cases) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    storeLe(bytes, c.field, c.value, 8);
    reseal(bytes);
    Error error = decodeError(bytes);
    EXPECT_EQ(error.code, ErrorCode::kCorrupt) << c.field << " = " << c.value;
    EXPECT_NE(error.message.find("x.tess"), std::string::npos);
  }
}

TEST(Header, DecodeRejectsAnEmptyBlockWithAnOffsetOrChecksum) {
  for (size_t field : {size_t(56), size_t(72)}) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    storeLe(bytes, 64, 0, 8);  // metadata length 0
    if (field == 56) storeLe(bytes, 72, 0, 8);
    if (field == 72) storeLe(bytes, 56, 0, 8);
    reseal(bytes);
    EXPECT_EQ(decodeError(bytes).code, ErrorCode::kCorrupt) << field;
  }
}

TEST(Header, DecodeRejectsARootTooSmallOrLargeForTheImageCount) {
  for (uint64_t length : {0ull, 127ull, 2ull * (32 + 32 * 32) + 1}) {
    std::vector<uint8_t> bytes = goldenHeaderBytes();
    storeLe(bytes, 40, length, 8);
    if (length == 0) storeLe(bytes, 32, 0, 8), storeLe(bytes, 48, 0, 8);
    reseal(bytes);
    Error error = decodeError(bytes);
    EXPECT_EQ(error.code, ErrorCode::kCorrupt) << length;
  }
}

TEST(Header, DecodeRejectsOversizedMetadataAsTooLarge) {
  std::vector<uint8_t> bytes = goldenHeaderBytes();
  storeLe(bytes, 16, 64ull << 20, 8);
  storeLe(bytes, 64, kMaxMetadataBytes + 1, 8);
  reseal(bytes);
  EXPECT_EQ(decodeError(bytes).code, ErrorCode::kTooLarge);
}

// ---- Root directory --------------------------------------------------------------------------

FileHeader rootHeader(uint32_t image_count) {
  FileHeader header;
  header.file_bytes = 0x10000;
  header.image_count = image_count;
  return header;
}

ImageRecord goldenImageRecord() {
  ImageRecord record;
  record.info.width_px = 100;
  record.info.height_px = 70;
  record.info.channels = 4;
  record.info.tile_size_px = 64;
  record.info.border_px = 2;
  record.info.level_count = 2;
  record.info.default_codec = Codec::kZstd;
  record.info.page_tiles_log2 = 5;
  record.info.srgb_downsample = true;
  record.levels = {{{0x1000, 24, 0xAB}, 0x1234}, {{0, 0, 0}, 0}};
  return record;
}

std::vector<uint8_t> goldenRootBytes() {
  std::vector<uint8_t> bytes = {
      0x64, 0x00, 0x00, 0x00,  // width 100
      0x46, 0x00, 0x00, 0x00,  // height 70
      0x04,                    // channels
      0x06,                    // log2 tile size
      0x02,                    // border
      0x02,                    // level count
      0x01,                    // codec zstd
      0x05,                    // log2 page side
      0x01,                    // flags: sRGB downsampling
      0x00,                    // reserved
  };
  bytes.resize(32, 0);
  const uint8_t level0[32] = {
      0x00, 0x10, 0, 0, 0, 0, 0, 0,  // page index offset 4096
      0x18, 0,    0, 0, 0, 0, 0, 0,  // length 24
      0xAB, 0,    0, 0, 0, 0, 0, 0,  // checksum
      0x34, 0x12, 0, 0, 0, 0, 0, 0,  // payload bytes
  };
  bytes.insert(bytes.end(), level0, level0 + 32);
  bytes.resize(96, 0);  // level 1: no pages, no payload
  return bytes;
}

void expectSameRecords(const std::vector<ImageRecord>& a, const std::vector<ImageRecord>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].info.width_px, b[i].info.width_px);
    EXPECT_EQ(a[i].info.height_px, b[i].info.height_px);
    EXPECT_EQ(a[i].info.channels, b[i].info.channels);
    EXPECT_EQ(a[i].info.tile_size_px, b[i].info.tile_size_px);
    EXPECT_EQ(a[i].info.border_px, b[i].info.border_px);
    EXPECT_EQ(a[i].info.level_count, b[i].info.level_count);
    EXPECT_EQ(a[i].info.default_codec, b[i].info.default_codec);
    EXPECT_EQ(a[i].info.page_tiles_log2, b[i].info.page_tiles_log2);
    EXPECT_EQ(a[i].info.srgb_downsample, b[i].info.srgb_downsample);
    EXPECT_EQ(a[i].info.sample_type, b[i].info.sample_type);
    EXPECT_EQ(a[i].levels, b[i].levels);
  }
}

TEST(RootDirectory, EncodeMatchesGoldenBytes) {
  EXPECT_EQ(encodeRootDirectory({goldenImageRecord()}), goldenRootBytes());
}

TEST(RootDirectory, DecodeOfGoldenBytesGivesEveryField) {
  auto decoded = decodeRootDirectory(goldenRootBytes(), rootHeader(1), "x.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  expectSameRecords(*decoded, {goldenImageRecord()});
}

TEST(RootDirectory, DecodeInvertsEncodeForSeveralImages) {
  ImageRecord second;
  second.info = {1, 300, 1, 2048, 16, 1, 8, Codec::kWebp, false, ""};
  second.levels = {{{0, 0, 0}, 0}};
  ImageRecord third;
  third.info = {4097, 4095, 3, 64, 0, 8, 3, Codec::kRaw, false, ""};
  for (uint32_t l = 0; l < 8; ++l) {
    uint64_t pages = uint64_t(pagesX(third.info, l)) * pagesY(third.info, l);
    third.levels.push_back({{0x2000 + l * 0x100, pages * 24, l * 7ull}, l * 3ull});
  }
  std::vector<ImageRecord> records = {goldenImageRecord(), second, third};
  auto decoded = decodeRootDirectory(encodeRootDirectory(records), rootHeader(3), "x.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  expectSameRecords(*decoded, records);
}

TEST(RootDirectory, DecodeRejectsEveryTruncation) {
  const std::vector<uint8_t> golden = goldenRootBytes();
  for (size_t length = 0; length < golden.size(); ++length) {
    std::vector<uint8_t> prefix(golden.begin(), golden.begin() + length);
    auto decoded = decodeRootDirectory(prefix, rootHeader(1), "x.tess");
    ASSERT_FALSE(decoded) << length;
    EXPECT_EQ(decoded.error().code, ErrorCode::kCorrupt) << length;
  }
}

TEST(RootDirectory, DecodeRejectsTrailingBytes) {
  std::vector<uint8_t> bytes = goldenRootBytes();
  bytes.push_back(0);
  auto decoded = decodeRootDirectory(bytes, rootHeader(1), "x.tess");
  ASSERT_FALSE(decoded);
  EXPECT_NE(decoded.error().message.find("trailing"), std::string::npos);
}

TEST(RootDirectory, DecodeRejectsFieldsOutOfBounds) {
  struct Case {
    const char* what;
    size_t offset;
    uint8_t value;
  };
  const Case cases[] = {
      {"zero width", 0, 0},
      {"channels 0", 8, 0},
      {"channels 5", 8, 5},
      {"tile 32", 9, 5},
      {"tile 4096", 9, 12},
      {"tile 2^255", 9, 255},
      {"border 17", 10, 17},
      {"too few levels", 11, 1},
      {"too many levels", 11, 3},
      {"page side 2^2", 13, 2},
      {"page side 2^9", 13, 9},
      {"unknown flag", 14, 2},
      {"reserved 15", 15, 1},
      {"reserved 16", 16, 1},
      {"reserved 31", 31, 1},
      {"page index length", 32 + 8, 48},
      {"page index inside header", 32 + 1, 0},
  };
  for (const Case& c : cases) {
    std::vector<uint8_t> bytes = goldenRootBytes();
    bytes[c.offset] = c.value;
    if (c.offset == 0) std::fill(bytes.begin(), bytes.begin() + 4, 0);
    auto decoded = decodeRootDirectory(bytes, rootHeader(1), "x.tess");
    EXPECT_FALSE(decoded) << c.what;
    if (!decoded) {
      EXPECT_NE(decoded.error().message.find("x.tess: image 0"), std::string::npos);
    }
  }
}

// Sample types (docs/format.md, "Sample types"): byte 15 of the image record, from minor 2.
TEST(RootDirectory, SampleTypeIsByteFifteenOfAMinorTwoFile) {
  for (SampleType type : {SampleType::kU8, SampleType::kU16, SampleType::kF32}) {
    ImageRecord record = goldenImageRecord();
    record.info.sample_type = type;
    std::vector<uint8_t> expected = goldenRootBytes();
    expected[15] = uint8_t(type);
    const std::vector<uint8_t> bytes = encodeRootDirectory({record});
    EXPECT_EQ(bytes, expected) << sampleTypeName(type);
    FileHeader header = rootHeader(1);
    header.version_minor = kSampleTypeMinorVersion;
    auto decoded = decodeRootDirectory(bytes, header, "x.tess");
    ASSERT_TRUE(decoded) << decoded.error().message;
    EXPECT_EQ((*decoded)[0].info.sample_type, type);
    EXPECT_EQ((*decoded)[0].info.storedTileBytes(), size_t(68 * 68 * 4 * sampleBytes(type)));
  }
}

TEST(RootDirectory, UnknownSampleTypeIsUnsupportedAndNamed) {
  std::vector<uint8_t> bytes = goldenRootBytes();
  bytes[15] = 3;
  FileHeader header = rootHeader(1);
  header.version_minor = kSampleTypeMinorVersion;
  auto decoded = decodeRootDirectory(bytes, header, "x.tess");
  ASSERT_FALSE(decoded);
  EXPECT_EQ(decoded.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(decoded.error().message.find("x.tess: image 0: sample type 3"), std::string::npos)
      << decoded.error().message;
}

TEST(RootDirectory, ByteFifteenIsReservedBeforeMinorTwo) {
  std::vector<uint8_t> bytes = goldenRootBytes();
  bytes[15] = uint8_t(SampleType::kF32);
  // Minor 0: a reserved field set, rejected (DecodeRejectsFieldsOutOfBounds covers it too).
  EXPECT_FALSE(decodeRootDirectory(bytes, rootHeader(1), "x.tess"));
  // Minor 1: a reserved field of an older minor's reader is ignored; the image is 8-bit.
  FileHeader header = rootHeader(1);
  header.version_minor = 1;
  auto decoded = decodeRootDirectory(bytes, header, "x.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ((*decoded)[0].info.sample_type, SampleType::kU8);
}

TEST(RootDirectory, OnlyWideImagesRaiseTheMinorVersion) {
  std::vector<ImageRecord> records = {goldenImageRecord(), goldenImageRecord()};
  EXPECT_EQ(minorVersionFor(records), kFormatVersionMinor);
  records[1].info.sample_type = SampleType::kU16;
  EXPECT_EQ(minorVersionFor(records), kSampleTypeMinorVersion);
}

TEST(RootDirectory, DecodeRejectsAWidthOverTheLimitAsTooLarge) {
  std::vector<uint8_t> bytes = goldenRootBytes();
  uint32_t width = kMaxImageSidePx + 1;
  std::memcpy(bytes.data(), &width, 4);  // little-endian host (x86, arm64)
  auto decoded = decodeRootDirectory(bytes, rootHeader(1), "x.tess");
  ASSERT_FALSE(decoded);
  EXPECT_EQ(decoded.error().code, ErrorCode::kTooLarge);
}

TEST(RootDirectory, DecodeRejectsAPageIndexOutsideTheFile) {
  std::vector<uint8_t> bytes = goldenRootBytes();
  FileHeader header = rootHeader(1);
  header.file_bytes = 0x1000 + 23;  // the 24-byte page index ends one byte past the file
  header.header_region_bytes = 4096;
  EXPECT_FALSE(decodeRootDirectory(bytes, header, "x.tess"));
}

TEST(RootDirectory, DecodeRejectsAPayloadTotalOverTheFileSize) {
  std::vector<uint8_t> bytes = goldenRootBytes();
  bytes[32 + 24 + 7] = 0x01;  // payload bytes 2^56
  EXPECT_FALSE(decodeRootDirectory(bytes, rootHeader(1), "x.tess"));
}

TEST(ValidateImageInfo, AcceptsEveryTileSizeAndBorderInBounds) {
  for (uint32_t tile = kMinTileSizePx; tile <= kMaxTileSizePx; tile *= 2) {
    for (uint32_t border : {0u, 1u, 4u, kMaxBorderPx}) {
      ImageInfo info{300, 1, 2, tile, border, 0, 5, Codec::kZstd, false, ""};
      EXPECT_TRUE(validateImageInfo(info, "img")) << tile << " " << border;
    }
  }
}

TEST(ValidateImageInfo, NamesTheImageInEveryRejection) {
  const ImageInfo good{300, 200, 3, 256, 0, 0, 5, Codec::kZstd, false, ""};
  std::vector<ImageInfo> bad(8, good);
  bad[0].width_px = 0;
  bad[1].height_px = kMaxImageSidePx + 1;
  bad[2].channels = 0;
  bad[3].channels = 5;
  bad[4].tile_size_px = 96;
  bad[5].tile_size_px = 4096;
  bad[6].border_px = 17;
  bad[7].page_tiles_log2 = 9;
  for (const ImageInfo& info : bad) {
    auto result = validateImageInfo(info, "scan.tif");
    ASSERT_FALSE(result);
    EXPECT_EQ(result.error().message.rfind("scan.tif: ", 0), 0u) << result.error().message;
  }
}

}  // namespace
}  // namespace tessera::detail
