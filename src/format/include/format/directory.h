#pragma once
// Page indexes and directory pages (docs/format.md, "Page index" and "Directory pages").
// A directory page lists the entries of a 2^n x 2^n block of tiles, so finding one tile of a
// terapixel image reads one page, never the whole directory.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

#include "format/header.h"

namespace tessera::detail {

inline constexpr uint32_t kPageRefBytes = 24;
inline constexpr uint32_t kTileEntryBytes = 24;

/// A page's location; length 0 means every tile of the page is empty.
using PageRef = BlockRef;

/// The tile block a page covers, clipped to the level's grid.
struct PageGeometry {
  uint32_t first_tile_x = 0;
  uint32_t first_tile_y = 0;
  uint32_t columns = 0;  ///< tiles across, 1..2^page_tiles_log2
  uint32_t rows = 0;     ///< tiles down
  uint64_t bytes() const { return uint64_t(columns) * rows * kTileEntryBytes; }
};

PageGeometry pageGeometry(const ImageInfo& info, uint32_t level, uint32_t page_x, uint32_t page_y);

std::vector<uint8_t> encodePageIndex(std::span<const PageRef> pages);
/// Decodes `count` page refs, each checked against the file size and the page's own size.
Result<std::vector<PageRef>> decodePageIndex(std::span<const uint8_t> bytes, const ImageInfo& info,
                                             uint32_t level, uint64_t file_bytes,
                                             const std::string& what);
/// Decodes one page ref at position `index` of a level's page index.
Result<PageRef> decodePageRef(std::span<const uint8_t> bytes, const ImageInfo& info, uint32_t level,
                              uint32_t index, uint64_t file_bytes, const std::string& what);

std::vector<uint8_t> encodeTileEntries(std::span<const TileEntry> entries);
/// Decodes a page's entries (row-major within the page) and checks each: kind known and not
/// procedural in v1, codec known, payload inside [header_region_bytes, file_bytes), reserved
/// fields zero, uniform colour only in the image's channels.
Result<std::vector<TileEntry>> decodeTileEntries(std::span<const uint8_t> bytes,
                                                 const ImageInfo& info, const FileHeader& header,
                                                 const std::string& what);

/// Largest payload a reader accepts for one tile: a codec that expands its input by more
/// than this is broken, and the bound stops a corrupt length from driving an allocation.
uint64_t maxPayloadBytes(const ImageInfo& info);

}  // namespace tessera::detail
