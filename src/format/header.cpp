#include "format/header.h"

#include <bit>
#include <cstring>

#include <fmt/format.h>

#include "format/byte_io.h"
#include "format/checksum.h"
#include "format/directory.h"

namespace tessera::detail {

namespace {

constexpr uint32_t kHeaderChecksumOffset = 120;
constexpr uint32_t kMinHeaderRegionBytes = 4096;

}  // namespace

void storeBlockRef(uint8_t* p, const BlockRef& block) {
  storeU64(p, block.offset_bytes);
  storeU64(p + 8, block.length_bytes);
  storeU64(p + 16, block.checksum);
}

BlockRef loadBlockRef(const uint8_t* p) {
  return {loadU64(p), loadU64(p + 8), loadU64(p + 16)};
}

Result<void> checkBlockInFile(const BlockRef& block, uint64_t file_bytes, const std::string& what) {
  if (block.length_bytes == 0) {
    if (block.offset_bytes != 0 || block.checksum != 0)
      return fail(ErrorCode::kCorrupt, what + ": empty block with non-zero offset or checksum");
    return {};
  }
  if (block.offset_bytes < kHeaderBytes || block.offset_bytes > file_bytes ||
      block.length_bytes > file_bytes - block.offset_bytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: block [{}, +{}) outside the file of {} bytes", what,
                            block.offset_bytes, block.length_bytes, file_bytes));
  return {};
}

std::vector<uint8_t> encodeHeader(const FileHeader& header) {
  std::vector<uint8_t> bytes(kHeaderBytes, 0);
  uint8_t* p = bytes.data();
  std::memcpy(p, kMagic, sizeof(kMagic));
  storeU16(p + 8, header.version_major);
  storeU16(p + 10, header.version_minor);
  storeU32(p + 12, header.header_region_bytes);
  storeU64(p + 16, header.file_bytes);
  storeU32(p + 24, header.image_count);
  storeBlockRef(p + 32, header.root);
  storeBlockRef(p + 56, header.metadata);
  storeU64(p + kHeaderChecksumOffset, checksum64({p, kHeaderChecksumOffset}));
  return bytes;
}

Result<FileHeader> decodeHeader(std::span<const uint8_t> bytes, const std::string& name) {
  if (bytes.size() < kHeaderBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} bytes is too short for a Tessera archive (header is {} bytes)",
                            name, bytes.size(), kHeaderBytes));
  const uint8_t* p = bytes.data();
  if (std::memcmp(p, kMagic, sizeof(kMagic)) != 0) {
    if (allZero(p, sizeof(kMagic)))
      return fail(ErrorCode::kCorrupt,
                  name + ": header never written (an interrupted build or not an archive)");
    return fail(ErrorCode::kCorrupt, name + ": not a Tessera archive (bad magic)");
  }
  FileHeader header;
  header.version_major = loadU16(p + 8);
  header.version_minor = loadU16(p + 10);
  // Version first: a newer major may have moved the checksum.
  if (header.version_major != kFormatVersionMajor)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: format version {}.{} is not readable by this build (reads {}.x)",
                            name, header.version_major, header.version_minor, kFormatVersionMajor));
  uint64_t stored_checksum = loadU64(p + kHeaderChecksumOffset);
  uint64_t actual_checksum = checksum64({p, kHeaderChecksumOffset});
  if (stored_checksum != actual_checksum)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: header checksum mismatch (stored {:016x}, computed {:016x})", name,
                            stored_checksum, actual_checksum));
  header.header_region_bytes = loadU32(p + 12);
  header.file_bytes = loadU64(p + 16);
  header.image_count = loadU32(p + 24);
  uint32_t flags = loadU32(p + 28);
  header.root = loadBlockRef(p + 32);
  header.metadata = loadBlockRef(p + 56);
  bool known_minor = header.version_minor <= kFormatVersionMinor;
  if (known_minor && (flags != 0 || !allZero(p + 80, 40)))
    return fail(ErrorCode::kCorrupt, name + ": reserved header fields are not zero");
  if (header.header_region_bytes < kMinHeaderRegionBytes ||
      header.header_region_bytes > kMaxHeaderRegionBytes || header.header_region_bytes % 4096)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: header region of {} bytes out of bounds",
                                                 name, header.header_region_bytes));
  if (header.file_bytes < header.header_region_bytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: recorded file size {} is smaller than the header region", name,
                            header.file_bytes));
  if (header.image_count == 0 || header.image_count > kMaxImages)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: image count {} out of bounds 1..{}", name,
                                                 header.image_count, kMaxImages));
  TESSERA_TRY(checkBlockInFile(header.root, header.file_bytes, name + ": root directory"));
  TESSERA_TRY(checkBlockInFile(header.metadata, header.file_bytes, name + ": metadata"));
  uint64_t min_root = uint64_t(header.image_count) * (kImageRecordBytes + kLevelRecordBytes);
  uint64_t max_root =
      uint64_t(header.image_count) * (kImageRecordBytes + kMaxLevels * kLevelRecordBytes);
  if (header.root.length_bytes < min_root || header.root.length_bytes > max_root)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: root directory of {} bytes cannot hold {} images", name,
                            header.root.length_bytes, header.image_count));
  if (header.metadata.length_bytes > kMaxMetadataBytes)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: metadata of {} bytes exceeds {} bytes", name,
                                                  header.metadata.length_bytes, kMaxMetadataBytes));
  return header;
}

uint32_t pagesX(const ImageInfo& info, uint32_t level) {
  uint32_t page = 1u << info.page_tiles_log2;
  return (info.tilesX(level) + page - 1) / page;
}

uint32_t pagesY(const ImageInfo& info, uint32_t level) {
  uint32_t page = 1u << info.page_tiles_log2;
  return (info.tilesY(level) + page - 1) / page;
}

Result<void> validateImageInfo(const ImageInfo& info, const std::string& what) {
  if (info.width_px == 0 || info.height_px == 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: zero dimension {}x{}", what, info.width_px, info.height_px));
  if (info.width_px > kMaxImageSidePx || info.height_px > kMaxImageSidePx)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {}x{} exceeds the {} px limit per side", what, info.width_px,
                            info.height_px, kMaxImageSidePx));
  if (info.channels < 1 || info.channels > 4)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: {} channels (1..4 supported)", what, info.channels));
  if (info.tile_size_px < kMinTileSizePx || info.tile_size_px > kMaxTileSizePx ||
      !std::has_single_bit(info.tile_size_px))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: tile size {} is not a power of two in {}..{}", what,
                            info.tile_size_px, kMinTileSizePx, kMaxTileSizePx));
  if (info.border_px > kMaxBorderPx)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: border {} exceeds {}", what, info.border_px, kMaxBorderPx));
  if (info.page_tiles_log2 < 3 || info.page_tiles_log2 > 8)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: directory page of 2^{} tiles out of 2^3..2^8", what,
                            info.page_tiles_log2));
  return {};
}

uint16_t minorVersionFor(std::span<const ImageRecord> images) {
  for (const ImageRecord& image : images)
    if (image.info.sample_type != SampleType::kU8) return kSampleTypeMinorVersion;
  return kFormatVersionMinor;
}

Result<SampleType> decodeSampleType(uint8_t value, const FileHeader& header,
                                    const std::string& what) {
  // Byte 15 is reserved before minor 2: files of minor 1 are read as 8-bit whatever it holds
  // (the reserved-field rule); minor 0 rejected it above.
  if (header.version_minor < kSampleTypeMinorVersion) return SampleType::kU8;
  if (value > uint8_t(SampleType::kF32))
    return fail(
        ErrorCode::kUnsupported,
        fmt::format("{}: sample type {} is not supported (0 u8, 1 u16, 2 f32 are)", what, value));
  return SampleType(value);
}

std::vector<uint8_t> encodeRootDirectory(const std::vector<ImageRecord>& images) {
  size_t total = 0;
  for (const auto& image : images)
    total += kImageRecordBytes + image.levels.size() * kLevelRecordBytes;
  std::vector<uint8_t> bytes(total, 0);
  uint8_t* p = bytes.data();
  for (const auto& image : images) {
    const ImageInfo& info = image.info;
    storeU32(p, info.width_px);
    storeU32(p + 4, info.height_px);
    p[8] = uint8_t(info.channels);
    p[9] = uint8_t(std::countr_zero(info.tile_size_px));
    p[10] = uint8_t(info.border_px);
    p[11] = uint8_t(image.levels.size());
    p[12] = uint8_t(info.default_codec);
    p[13] = uint8_t(info.page_tiles_log2);
    p[14] = info.srgb_downsample ? 1 : 0;
    p[15] = uint8_t(info.sample_type);
    p += kImageRecordBytes;
    for (const auto& level : image.levels) {
      storeBlockRef(p, level.page_index);
      storeU64(p + 24, level.payload_bytes);
      p += kLevelRecordBytes;
    }
  }
  return bytes;
}

Result<std::vector<ImageRecord>> decodeRootDirectory(std::span<const uint8_t> bytes,
                                                     const FileHeader& header,
                                                     const std::string& name) {
  bool known_minor = header.version_minor <= kFormatVersionMinor;
  std::vector<ImageRecord> images;
  images.reserve(header.image_count);
  size_t pos = 0;
  for (uint32_t i = 0; i < header.image_count; ++i) {
    std::string what = fmt::format("{}: image {}", name, i);
    if (bytes.size() - pos < kImageRecordBytes)
      return fail(ErrorCode::kCorrupt, what + ": root directory ends inside the image record");
    const uint8_t* p = bytes.data() + pos;
    ImageRecord record;
    ImageInfo& info = record.info;
    info.width_px = loadU32(p);
    info.height_px = loadU32(p + 4);
    info.channels = p[8];
    if (p[9] > 11)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: tile size 2^{} out of bounds", what, p[9]));
    info.tile_size_px = 1u << p[9];
    info.border_px = p[10];
    uint32_t level_count = p[11];
    info.default_codec = Codec(p[12]);
    info.page_tiles_log2 = p[13];
    uint8_t flags = p[14];
    info.srgb_downsample = flags & 1;
    if (known_minor && ((flags & ~1u) || p[15] || !allZero(p + 16, 16)))
      return fail(ErrorCode::kCorrupt, what + ": reserved image-record fields are not zero");
    TESSERA_ASSIGN_OR_RETURN(info.sample_type, decodeSampleType(p[15], header, what));
    TESSERA_TRY(validateImageInfo(info, what));
    uint32_t expected_levels = levelCountFor(info.width_px, info.height_px, info.tile_size_px);
    if (level_count != expected_levels)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: {} levels recorded, geometry implies {}",
                                                   what, level_count, expected_levels));
    info.level_count = level_count;
    pos += kImageRecordBytes;
    if ((bytes.size() - pos) / kLevelRecordBytes < level_count)
      return fail(ErrorCode::kCorrupt, what + ": root directory ends inside the level records");
    for (uint32_t level = 0; level < level_count; ++level) {
      const uint8_t* q = bytes.data() + pos;
      LevelRecord level_record{loadBlockRef(q), loadU64(q + 24)};
      std::string level_what = fmt::format("{} level {}", what, level);
      TESSERA_TRY(
          checkBlockInFile(level_record.page_index, header.file_bytes, level_what + " page index"));
      uint64_t pages = uint64_t(pagesX(info, level)) * pagesY(info, level);
      uint64_t length = level_record.page_index.length_bytes;
      if (length != 0 && length != pages * kPageRefBytes)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: page index of {} bytes, the grid needs {} pages of 24 bytes",
                                level_what, length, pages));
      if (level_record.payload_bytes > header.file_bytes)
        return fail(ErrorCode::kCorrupt, level_what + ": payload total exceeds the file size");
      record.levels.push_back(level_record);
      pos += kLevelRecordBytes;
    }
    images.push_back(std::move(record));
  }
  if (pos != bytes.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {} trailing bytes after the root directory",
                                                 name, bytes.size() - pos));
  return images;
}

}  // namespace tessera::detail
