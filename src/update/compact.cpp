// compactArchive: every live block of an archive copied into a fresh file, payloads in the
// clustering order its metadata records, through a temporary renamed into place.
#include <fmt/format.h>

#include <tessera/archive.h>

#include "archive_tail.h"
#include "builder/directory_pages.h"
#include "format/checksum.h"
#include "format/tile_order.h"
#include "output/file_appender.h"
#include "output/output_file.h"
#include "update/archive_update.h"

namespace tessera::detail {

namespace {

TileOrder recordedOrder(const nlohmann::json& metadata) {
  const auto build = metadata.find("build");
  if (build == metadata.end() || !build->is_object()) return TileOrder::kHilbert;
  // Any order makes a valid archive: a name of another type, like an unknown one, is Hilbert.
  const auto found = build->find("order");
  const std::string order = found != build->end() && found->is_string() ? found->get<std::string>()
                                                                        : std::string("hilbert");
  return order == "quadtree"    ? TileOrder::kQuadtree
         : order == "row-major" ? TileOrder::kRowMajor
                                : TileOrder::kHilbert;
}

/// The header region under construction: blocks go into it while they fit, else to the tail.
struct RegionPlacer {
  std::vector<uint8_t>& region;
  size_t used;
  FileAppender& appender;
  Result<BlockRef> place(std::span<const uint8_t> bytes) {
    if (bytes.empty()) return BlockRef{};
    const uint64_t checksum = checksum64(bytes);
    if (region.size() - used >= bytes.size()) {
      std::copy(bytes.begin(), bytes.end(), region.begin() + used);
      used += bytes.size();
      return BlockRef{used - bytes.size(), bytes.size(), checksum};
    }
    TESSERA_ASSIGN_OR_RETURN(uint64_t offset, appender.append(bytes));
    return BlockRef{offset, bytes.size(), checksum};
  }
};

/// Copies image `image`'s payloads in `order` and returns its entries per level, placed.
Result<std::vector<std::vector<TileEntry>>> copyPayloads(const Archive& archive, uint32_t image,
                                                         TileOrder order, FileAppender& appender) {
  const ImageInfo& info = archive.images()[image];
  std::vector<std::vector<TileEntry>> entries(info.level_count);
  for (uint32_t level = 0; level < info.level_count; ++level)
    entries[level].resize(size_t(info.tilesX(level)) * info.tilesY(level));
  for (const TileId& tile : tileOrder(info, image, order)) {
    TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(tile));
    if (entry.hasPayload()) {
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload, archive.readPayload(tile, entry));
      TESSERA_ASSIGN_OR_RETURN(entry.offset_bytes, appender.append(payload));
    }
    entries[tile.level][size_t(tile.y) * info.tilesX(tile.level) + tile.x] = entry;
  }
  return entries;
}

}  // namespace

Result<CompactReport> compactArchive(const std::string& path, const std::string& output) {
  // The lock keeps updates out while the copy is made.
  TESSERA_ASSIGN_OR_RETURN(ArchiveTail tail, ArchiveTail::open(path));
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<Archive> archive, Archive::openFile(path));
  TESSERA_ASSIGN_OR_RETURN(TempFile out, TempFile::create(output));
  const TileOrder order = recordedOrder(tail.metadata());
  const uint32_t region_bytes = tail.header().header_region_bytes;
  FileAppender appender(out, region_bytes);
  std::vector<ImageRecord> records = tail.records();
  std::vector<std::vector<uint8_t>> indexes;  // per image and level, in order
  for (uint32_t image = 0; image < records.size(); ++image) {
    TESSERA_ASSIGN_OR_RETURN(auto entries, copyPayloads(*archive, image, order, appender));
    for (uint32_t level = 0; level < entries.size(); ++level) {
      TESSERA_ASSIGN_OR_RETURN(
          std::vector<uint8_t> index,
          writeLevelPages(records[image].info, level, entries[level], appender));
      indexes.push_back(std::move(index));
    }
  }
  std::vector<uint8_t> region(region_bytes, 0);
  size_t root_bytes = 0;
  for (const ImageRecord& record : records)
    root_bytes += kImageRecordBytes + record.levels.size() * kLevelRecordBytes;
  if (kHeaderBytes + root_bytes > region.size())
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: root directory of {} bytes does not fit the header region", path,
                            root_bytes));
  RegionPlacer placer{region, kHeaderBytes + root_bytes, appender};
  size_t next_index = 0;
  for (ImageRecord& record : records)
    for (LevelRecord& level : record.levels) {
      TESSERA_ASSIGN_OR_RETURN(level.page_index, placer.place(indexes[next_index++]));
    }
  nlohmann::json metadata = tail.metadata();
  metadata.erase("update");
  const std::string json = metadata.dump();
  FileHeader header = tail.header();
  TESSERA_ASSIGN_OR_RETURN(
      header.metadata, placer.place({reinterpret_cast<const uint8_t*>(json.data()), json.size()}));
  const std::vector<uint8_t> root = encodeRootDirectory(records);
  std::copy(root.begin(), root.end(), region.begin() + kHeaderBytes);
  header.root = {kHeaderBytes, root.size(), checksum64(root)};
  TESSERA_TRY(appender.flush());
  header.file_bytes = appender.end();
  TESSERA_TRY(out.pwrite(kHeaderBytes, std::span(region).subspan(kHeaderBytes)));
  // The header last (docs/format.md, "Commit marker"); commit() syncs and renames.
  TESSERA_TRY(out.pwrite(0, encodeHeader(header)));
  TESSERA_TRY(out.commit());
  return CompactReport{tail.header().file_bytes, header.file_bytes};
}

}  // namespace tessera::detail
