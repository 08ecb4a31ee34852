#include "level_pages.h"

#include <fmt/format.h>

#include "format/directory.h"

namespace tessera::detail {

namespace {

/// The committed page references of a level: all absent when it has no page index.
Result<std::vector<PageRef>> committedPageRefs(const ArchiveTail& tail, const ImageInfo& info,
                                               uint32_t level, const BlockRef& index,
                                               const std::string& what) {
  const size_t pages = size_t(pagesX(info, level)) * pagesY(info, level);
  if (index.length_bytes == 0) return std::vector<PageRef>(pages);
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, tail.readBlock(index, what));
  return decodePageIndex(bytes, info, level, tail.header().file_bytes, tail.path() + ": " + what);
}

}  // namespace

Result<void> rewriteLevel(ArchiveTail& tail, uint32_t image, uint32_t level,
                          const LevelChanges& changes) {
  if (changes.empty()) return {};
  const ImageInfo info = tail.records()[image].info;
  LevelRecord record = tail.records()[image].levels[level];
  const std::string what = fmt::format("image {} level {}", image, level);
  TESSERA_ASSIGN_OR_RETURN(
      std::vector<PageRef> refs,
      committedPageRefs(tail, info, level, record.page_index, what + " page index"));
  const uint32_t tiles_x = info.tilesX(level);
  const uint32_t page_shift = info.page_tiles_log2;
  // Changes grouped by page, in page order: each page is read and written once.
  std::map<uint64_t, std::vector<std::pair<uint64_t, const TileEntry*>>> by_page;
  const uint32_t pages_x = pagesX(info, level);
  for (const auto& [index, entry] : changes) {
    const uint32_t x = uint32_t(index % tiles_x), y = uint32_t(index / tiles_x);
    by_page[uint64_t(y >> page_shift) * pages_x + (x >> page_shift)].push_back({index, &entry});
  }
  for (const auto& [page, tiles] : by_page) {
    const PageGeometry geometry =
        pageGeometry(info, level, uint32_t(page % pages_x), uint32_t(page / pages_x));
    const std::string page_what = fmt::format("{} page {}", what, page);
    std::vector<TileEntry> entries(size_t(geometry.columns) * geometry.rows);
    if (refs[page].length_bytes) {
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, tail.readBlock(refs[page], page_what));
      TESSERA_ASSIGN_OR_RETURN(
          entries, decodeTileEntries(bytes, info, tail.header(), tail.path() + ": " + page_what));
      tail.addDeadBytes(refs[page].length_bytes);
    }
    for (const auto& [index, entry] : tiles) {
      const uint32_t x = uint32_t(index % tiles_x), y = uint32_t(index / tiles_x);
      TileEntry& slot = entries[size_t(y - geometry.first_tile_y) * geometry.columns +
                                (x - geometry.first_tile_x)];
      if (slot.hasPayload()) {
        tail.addDeadBytes(slot.length_bytes);
        record.payload_bytes -= slot.length_bytes;
      }
      slot = *entry;
      if (slot.hasPayload()) record.payload_bytes += slot.length_bytes;
    }
    bool all_empty = true;
    for (const TileEntry& entry : entries) all_empty = all_empty && entry.kind == TileKind::kEmpty;
    refs[page] = PageRef{};
    if (!all_empty) {
      TESSERA_ASSIGN_OR_RETURN(refs[page], tail.append(encodeTileEntries(entries)));
    }
  }
  tail.addDeadBytes(record.page_index.length_bytes);
  record.page_index = BlockRef{};
  bool any_page = false;
  for (const PageRef& ref : refs) any_page = any_page || ref.length_bytes != 0;
  if (any_page) {
    TESSERA_ASSIGN_OR_RETURN(record.page_index, tail.append(encodePageIndex(refs)));
  }
  tail.records()[image].levels[level] = record;
  return {};
}

}  // namespace tessera::detail
