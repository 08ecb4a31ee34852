#include "format/directory.h"

#include <algorithm>

#include <fmt/format.h>

#include "format/byte_io.h"

namespace tessera::detail {

PageGeometry pageGeometry(const ImageInfo& info, uint32_t level, uint32_t page_x, uint32_t page_y) {
  uint32_t side = 1u << info.page_tiles_log2;
  PageGeometry page;
  page.first_tile_x = page_x * side;
  page.first_tile_y = page_y * side;
  page.columns = std::min(side, info.tilesX(level) - page.first_tile_x);
  page.rows = std::min(side, info.tilesY(level) - page.first_tile_y);
  return page;
}

std::vector<uint8_t> encodePageIndex(std::span<const PageRef> pages) {
  std::vector<uint8_t> bytes(pages.size() * kPageRefBytes);
  uint8_t* p = bytes.data();
  for (const PageRef& page : pages) {
    storeU64(p, page.offset_bytes);
    storeU64(p + 8, page.length_bytes);
    storeU64(p + 16, page.checksum);
    p += kPageRefBytes;
  }
  return bytes;
}

Result<PageRef> decodePageRef(std::span<const uint8_t> bytes, const ImageInfo& info, uint32_t level,
                              uint32_t index, uint64_t file_bytes, const std::string& what) {
  TESSERA_CHECK(bytes.size() >= kPageRefBytes) << "page ref needs 24 bytes";
  const uint8_t* p = bytes.data();
  PageRef page{loadU64(p), loadU64(p + 8), loadU64(p + 16)};
  uint32_t pages_x = pagesX(info, level);
  PageGeometry geometry = pageGeometry(info, level, index % pages_x, index / pages_x);
  if (page.length_bytes == 0) {
    if (page.offset_bytes != 0 || page.checksum != 0)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: page {} is empty but has an offset or checksum", what, index));
    return page;
  }
  if (page.length_bytes != geometry.bytes())
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: page {} has {} bytes, its {}x{} tiles need {}", what, index,
                            page.length_bytes, geometry.columns, geometry.rows, geometry.bytes()));
  if (page.offset_bytes < kHeaderBytes || page.offset_bytes > file_bytes ||
      page.length_bytes > file_bytes - page.offset_bytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: page {} at [{}, +{}) outside the file", what,
                                                 index, page.offset_bytes, page.length_bytes));
  return page;
}

Result<std::vector<PageRef>> decodePageIndex(std::span<const uint8_t> bytes, const ImageInfo& info,
                                             uint32_t level, uint64_t file_bytes,
                                             const std::string& what) {
  uint64_t count = uint64_t(pagesX(info, level)) * pagesY(info, level);
  if (bytes.size() != count * kPageRefBytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: page index of {} bytes, expected {}", what,
                                                 bytes.size(), count * kPageRefBytes));
  std::vector<PageRef> pages;
  pages.reserve(count);
  for (uint32_t i = 0; i < count; ++i) {
    TESSERA_ASSIGN_OR_RETURN(PageRef page, decodePageRef(bytes.subspan(size_t(i) * kPageRefBytes),
                                                         info, level, i, file_bytes, what));
    pages.push_back(page);
  }
  return pages;
}

std::vector<uint8_t> encodeTileEntries(std::span<const TileEntry> entries) {
  std::vector<uint8_t> bytes(entries.size() * kTileEntryBytes, 0);
  uint8_t* p = bytes.data();
  for (const TileEntry& entry : entries) {
    if (entry.kind == TileKind::kUniform)
      storeU32(p, entry.uniform_rgba);
    else
      storeU64(p, entry.offset_bytes);
    storeU32(p + 8, entry.length_bytes);
    p[12] = uint8_t(entry.kind);
    p[13] = uint8_t(entry.codec);
    storeU64(p + 16, entry.checksum);
    p += kTileEntryBytes;
  }
  return bytes;
}

uint64_t maxPayloadBytes(const ImageInfo& info) {
  return uint64_t(info.storedTileBytes()) * 2 + 65536;
}

Result<std::vector<TileEntry>> decodeTileEntries(std::span<const uint8_t> bytes,
                                                 const ImageInfo& info, const FileHeader& header,
                                                 const std::string& what) {
  if (bytes.size() % kTileEntryBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} bytes is not a whole number of entries", what, bytes.size()));
  bool known_minor = header.version_minor <= kFormatVersionMinor;
  size_t count = bytes.size() / kTileEntryBytes;
  std::vector<TileEntry> entries(count);
  uint64_t max_payload = maxPayloadBytes(info);
  for (size_t i = 0; i < count; ++i) {
    const uint8_t* p = bytes.data() + i * kTileEntryBytes;
    TileEntry& entry = entries[i];
    uint8_t kind = p[12];
    uint8_t codec = p[13];
    if (known_minor && loadU16(p + 14) != 0)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: entry {} reserved field not zero", what, i));
    entry.length_bytes = loadU32(p + 8);
    entry.checksum = loadU64(p + 16);
    switch (kind) {
      case uint8_t(TileKind::kEmpty):
        if (!allZero(p, kTileEntryBytes))
          return fail(ErrorCode::kCorrupt, fmt::format("{}: empty entry {} has data", what, i));
        entry.kind = TileKind::kEmpty;
        break;
      case uint8_t(TileKind::kUniform): {
        // Eight bytes cannot hold four float samples, so wider samples have no uniform tiles.
        if (info.sample_type != SampleType::kU8)
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: uniform entry {} in an image of {} samples", what, i,
                                  sampleTypeName(info.sample_type)));
        entry.kind = TileKind::kUniform;
        entry.uniform_rgba = loadU32(p);
        // Channels the image does not have must be zero so a colour has one encoding.
        uint32_t unused_mask = info.channels >= 4 ? 0 : ~0u << (8 * info.channels);
        if ((entry.uniform_rgba & unused_mask) || loadU32(p + 4) || entry.length_bytes ||
            entry.checksum || codec)
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: uniform entry {} has stray fields", what, i));
        break;
      }
      case uint8_t(TileKind::kEncoded): {
        entry.kind = TileKind::kEncoded;
        entry.offset_bytes = loadU64(p);
        if (codec > uint8_t(Codec::kBc7))
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: entry {} has unknown codec {}", what, i, codec));
        entry.codec = Codec(codec);
        if (!codecSupportsSampleType(entry.codec, info.sample_type))
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: entry {} codec {} cannot hold {} samples", what, i,
                                  codecName(entry.codec), sampleTypeName(info.sample_type)));
        if (entry.length_bytes == 0 || entry.length_bytes > max_payload)
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: entry {} payload length {} out of 1..{}", what, i,
                                  entry.length_bytes, max_payload));
        if (entry.offset_bytes < header.header_region_bytes ||
            entry.offset_bytes > header.file_bytes ||
            entry.length_bytes > header.file_bytes - entry.offset_bytes)
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: entry {} payload [{}, +{}) outside the payload area", what,
                                  i, entry.offset_bytes, entry.length_bytes));
        break;
      }
      case uint8_t(TileKind::kProcedural):
        return fail(ErrorCode::kUnsupported,
                    fmt::format("{}: entry {} is procedural, which format 1.0 readers do not "
                                "generate",
                                what, i));
      default:
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: entry {} has unknown kind {}", what, i, kind));
    }
  }
  return entries;
}

}  // namespace tessera::detail
