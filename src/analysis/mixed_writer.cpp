#include "mixed_writer.h"

#include <cstring>
#include <functional>
#include <map>
#include <string_view>

#include <fmt/format.h>

#include "format/checksum.h"
#include "format/directory.h"
#include "format/header.h"
#include "format/sections.h"
#include "format/tile_order.h"
#include "builder/directory_pages.h"
#include "output/file_appender.h"

namespace tessera::detail {

namespace {

/// Identical pages (a tile under one base instance, and its neighbours) are stored once; two
/// independent 64-bit hashes and the length make a false match negligible.
struct PageKey {
  uint64_t checksum;
  size_t second_hash;
  size_t length;
  auto operator<=>(const PageKey&) const = default;
};

// The page as stored: brush ids renumbered to the stored brushes.
Result<std::vector<uint8_t>> storedPage(const TempFile& spool, const MixedTile& tile,
                                        const MixedBrushes& brushes, const std::string& what) {
  std::vector<uint8_t> bytes(tile.page_length);
  TESSERA_TRY(spool.pread(tile.page_offset, bytes));
  std::vector<TileClip> clips;
  TESSERA_ASSIGN_OR_RETURN(std::vector<BrushInstance> instances,
                           decodeInstancePage(bytes, uint32_t(brushes.remap.size()), what, &clips));
  for (BrushInstance& instance : instances) {
    const int64_t stored = brushes.remap[instance.brush];
    TESSERA_CHECK(stored >= 0) << what << ": a procedural tile draws brush " << instance.brush
                               << ", which is not stored";
    instance.brush = uint32_t(stored);
  }
  return encodeInstancePage(instances, clips);
}

// Payloads and pages in the clustering order; fills the final entries.
Result<void> placeTiles(const TempFile& spool, const ImageInfo& info,
                        const std::vector<std::vector<MixedTile>>& tiles,
                        const MixedBrushes& brushes, TileOrder order, FileAppender& appender,
                        std::vector<std::vector<TileEntry>>& entries, MixedWritten& written) {
  std::map<PageKey, std::pair<uint64_t, uint32_t>> pages;
  std::vector<uint8_t> payload;
  entries.resize(info.level_count);
  for (uint32_t l = 0; l < info.level_count; ++l) entries[l].resize(tiles[l].size());
  for (const TileId& id : tileOrder(info, 0, order)) {
    const size_t slot = size_t(id.y) * info.tilesX(id.level) + id.x;
    const MixedTile& tile = tiles[id.level][slot];
    TileEntry& entry = entries[id.level][slot];
    if (tile.procedural) {
      TESSERA_ASSIGN_OR_RETURN(
          std::vector<uint8_t> page,
          storedPage(spool, tile, brushes, fmt::format("tile ({},{},{})", id.level, id.x, id.y)));
      const uint64_t checksum = checksum64(page);
      PageKey key{
          checksum,
          std::hash<std::string_view>{}({reinterpret_cast<const char*>(page.data()), page.size()}),
          page.size()};
      auto it = pages.find(key);
      if (it == pages.end()) {
        TESSERA_ASSIGN_OR_RETURN(uint64_t offset, appender.append(page));
        it = pages.emplace(key, std::make_pair(offset, uint32_t(page.size()))).first;
        written.page_bytes += page.size();
      }
      entry = proceduralEntry(it->second.first, it->second.second, checksum);
      continue;
    }
    entry.kind = tile.baked_kind;
    entry.uniform_rgba = tile.uniform_rgba;
    if (tile.baked_kind != TileKind::kEncoded) continue;
    entry.codec = info.default_codec;
    entry.length_bytes = tile.payload_length;
    entry.checksum = tile.payload_checksum;
    payload.resize(tile.payload_length);
    TESSERA_TRY(spool.pread(tile.payload_offset, payload));
    TESSERA_ASSIGN_OR_RETURN(entry.offset_bytes, appender.append(payload));
    written.baked_payload_bytes += tile.payload_length;
  }
  return {};
}

Result<ProceduralImageRecord> placePicture(const MixedPicture& picture, FileAppender& appender) {
  ProceduralImageRecord record;
  TESSERA_ASSIGN_OR_RETURN(record.block.offset_bytes, appender.append(picture.payload));
  record.block.length_bytes = picture.payload.size();
  record.block.checksum = checksum64(picture.payload);
  record.width_px = picture.width_px;
  record.height_px = picture.height_px;
  record.channels = picture.channels;
  record.codec = picture.codec;
  return record;
}

// Directory pages (coarse levels first) and each level's page index bytes.
Result<std::vector<std::vector<uint8_t>>> placeDirectory(
    const ImageInfo& info, const std::vector<std::vector<TileEntry>>& entries,
    FileAppender& appender, ImageRecord& record) {
  std::vector<std::vector<uint8_t>> indexes(info.level_count);
  record.info = info;
  record.levels.resize(info.level_count);
  for (uint32_t l = info.level_count; l-- > 0;) {
    TESSERA_ASSIGN_OR_RETURN(indexes[l], writeLevelPages(info, l, entries[l], appender));
    uint64_t payload_total = 0;
    for (const TileEntry& entry : entries[l]) payload_total += entry.length_bytes;
    record.levels[l].payload_bytes = payload_total;
  }
  return indexes;
}

}  // namespace

Result<MixedWritten> writeMixedArchive(const TempFile& spool, const ImageInfo& info,
                                       const std::vector<std::vector<MixedTile>>& tiles,
                                       const MixedBrushes& brushes, TileOrder order,
                                       const nlohmann::json& metadata, const TempFile& out) {
  MixedWritten written;
  FileAppender appender(out, kHeaderRegionBytes);
  std::vector<std::vector<TileEntry>> entries;
  TESSERA_TRY(placeTiles(spool, info, tiles, brushes, order, appender, entries, written));

  const bool procedural = !brushes.brushes.empty();
  ProceduralDirectory directory;
  if (procedural) {
    for (const MixedPicture& picture : brushes.pictures) {
      TESSERA_ASSIGN_OR_RETURN(ProceduralImageRecord record, placePicture(picture, appender));
      directory.images.push_back(record);
      written.brush_bytes += picture.payload.size();
    }
    if (brushes.layer) {
      TESSERA_ASSIGN_OR_RETURN(directory.height_layer, placePicture(*brushes.layer, appender));
      written.brush_bytes += brushes.layer->payload.size();
    }
    directory.brushes = brushes.brushes;
  }

  std::vector<ImageRecord> records(1);
  TESSERA_ASSIGN_OR_RETURN(std::vector<std::vector<uint8_t>> indexes,
                           placeDirectory(info, entries, appender, records[0]));

  // The small blocks go into the header region while they fit (one read opens the archive).
  const uint64_t root_bytes = kImageRecordBytes + uint64_t(info.level_count) * kLevelRecordBytes;
  std::vector<uint8_t> region(kHeaderRegionBytes, 0);
  uint64_t region_used = kHeaderBytes + root_bytes;
  auto place = [&](const std::vector<uint8_t>& bytes) -> Result<BlockRef> {
    BlockRef ref{0, bytes.size(), bytes.empty() ? 0 : checksum64(bytes)};
    if (bytes.empty()) return ref;
    if (region_used + bytes.size() <= kHeaderRegionBytes) {
      ref.offset_bytes = region_used;
      std::memcpy(region.data() + region_used, bytes.data(), bytes.size());
      region_used += bytes.size();
      return ref;
    }
    TESSERA_ASSIGN_OR_RETURN(ref.offset_bytes, appender.append(bytes));
    return ref;
  };
  for (uint32_t l = info.level_count; l-- > 0;) {
    TESSERA_ASSIGN_OR_RETURN(records[0].levels[l].page_index, place(indexes[l]));
  }
  BlockRef sections_ref;
  if (procedural) {
    TESSERA_ASSIGN_OR_RETURN(const BlockRef directory_ref,
                             place(encodeProceduralDirectory(directory)));
    const SectionEntry section{uint32_t(SectionKind::kProcedural), directory_ref};
    TESSERA_ASSIGN_OR_RETURN(sections_ref, place(encodeSectionTable({&section, 1})));
  }
  const std::string text = metadata.dump();
  if (text.size() > kMaxMetadataBytes)
    return fail(ErrorCode::kTooLarge, out.finalPath() + ": metadata exceeds 16 MiB");
  TESSERA_ASSIGN_OR_RETURN(BlockRef metadata_ref,
                           place(std::vector<uint8_t>(text.begin(), text.end())));
  TESSERA_TRY(appender.flush());

  const std::vector<uint8_t> root = encodeRootDirectory(records);
  std::memcpy(region.data() + kHeaderBytes, root.data(), root.size());
  FileHeader header;
  header.file_bytes = std::max<uint64_t>(appender.end(), kHeaderRegionBytes);
  header.image_count = 1;
  header.root = {kHeaderBytes, root.size(), checksum64(root)};
  header.metadata = metadata_ref;
  // Everything but the header first; the header, the commit marker, last.
  TESSERA_TRY(out.pwrite(kHeaderBytes, std::span(region).subspan(kHeaderBytes)));
  std::vector<uint8_t> header_bytes = encodeHeader(header);
  if (procedural) stampSectionTableRef(header_bytes, sections_ref);
  TESSERA_TRY(out.pwrite(0, header_bytes));
  written.file_bytes = header.file_bytes;
  return written;
}

}  // namespace tessera::detail
