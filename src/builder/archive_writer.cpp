#include "archive_writer.h"

#include <cstring>

#include <fmt/format.h>

#include <tessera/archive.h>

#include "format/checksum.h"
#include "format/directory.h"
#include "format/header.h"
#include "format/tile_order.h"
#include "builder/directory_pages.h"
#include "output/file_appender.h"

namespace tessera::detail {

namespace {

struct PlacedBlock {
  BlockRef ref;
  std::vector<uint8_t> bytes;
};

/// Per image, per level, the entries as the archive stores them: [image][level][slot].
using ArchiveEntries = std::vector<std::vector<std::vector<TileEntry>>>;

/// What the payload pass wrote.
struct CopiedPayloads {
  ArchiveEntries entries;  ///< with the payloads' offsets in the output
  uint64_t payload_bytes = 0;
};

/// The directory as written: image records (page indexes not placed yet) and, per image, per
/// level from the coarsest, its page index (empty bytes for a level without pages).
struct WrittenDirectory {
  std::vector<ImageRecord> records;
  std::vector<PlacedBlock> page_indexes;
};

/// The first kHeaderRegionBytes of the file: the header, the root directory, then the page
/// indexes and metadata that fit, so that one read opens the archive.
class HeaderRegion {
 public:
  explicit HeaderRegion(uint64_t root_bytes)
      : bytes_(kHeaderRegionBytes, 0), used_(kHeaderBytes + root_bytes) {}
  /// Places `block` in the region while it fits, else at the end of the file.
  Result<void> place(PlacedBlock& block, FileAppender& appender) {
    if (block.bytes.empty()) return {};
    if (used_ + block.bytes.size() <= kHeaderRegionBytes) {
      block.ref.offset_bytes = used_;
      std::memcpy(bytes_.data() + used_, block.bytes.data(), block.bytes.size());
      used_ += block.bytes.size();
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(block.ref.offset_bytes, appender.append(block.bytes));
    return {};
  }
  std::span<uint8_t> bytes() { return bytes_; }

 private:
  std::vector<uint8_t> bytes_;
  uint64_t used_;
};

/// The entries of `image` as stored, without payload offsets (those come with the copy).
std::vector<std::vector<TileEntry>> entriesOf(const SpooledImage& image) {
  std::vector<std::vector<TileEntry>> levels(image.entries.size());
  for (uint32_t l = 0; l < image.entries.size(); ++l) {
    levels[l].resize(image.entries[l].size());
    for (size_t k = 0; k < image.entries[l].size(); ++k) {
      const SpoolEntry& spooled = image.entries[l][k];
      TileEntry& entry = levels[l][k];
      entry.kind = spooled.kind;
      entry.uniform_rgba = spooled.uniform_rgba;
      if (spooled.kind == TileKind::kEncoded) {
        entry.codec = spooled.codec;
        entry.length_bytes = spooled.length_bytes;
        entry.checksum = spooled.checksum;
      }
    }
  }
  return levels;
}

/// Copies the payloads to the output in the clustering order, in runs of up to
/// kPayloadRunBytes that `append` places. The entries are copies, so the caller's spool
/// offsets stay intact.
Result<CopiedPayloads> copyPayloads(const PayloadRunAppender& append,
                                    std::span<const SpooledImage> images, TileOrder order,
                                    FileAppender& appender) {
  CopiedPayloads copied;
  copied.entries.resize(images.size());
  std::vector<RunTile> run;
  std::vector<TileEntry*> placed;  // run[k]'s stored entry
  size_t run_bytes = 0;
  auto flush_run = [&]() -> Result<void> {
    if (run.empty()) return {};
    uint64_t offset = appender.end();
    TESSERA_TRY(append(run, run_bytes, appender));
    TESSERA_CHECK(appender.end() == offset + run_bytes) << "a run appended the wrong length";
    for (size_t k = 0; k < run.size(); ++k) {
      placed[k]->offset_bytes = offset;
      offset += run[k].entry->length_bytes;
    }
    copied.payload_bytes += run_bytes;
    run.clear();
    placed.clear();
    run_bytes = 0;
    return {};
  };
  for (uint32_t i = 0; i < images.size(); ++i) {
    const SpooledImage& image = images[i];
    auto& levels = copied.entries[i];
    levels = entriesOf(image);
    for (const TileId& tile : tileOrder(image.info, i, order)) {
      size_t slot = size_t(tile.y) * image.info.tilesX(tile.level) + tile.x;
      const SpoolEntry& spooled = image.entries[tile.level][slot];
      if (spooled.kind != TileKind::kEncoded) continue;
      if (run_bytes + spooled.length_bytes > kPayloadRunBytes) TESSERA_TRY(flush_run());
      run.push_back({tile, &spooled});
      placed.push_back(&levels[tile.level][slot]);
      run_bytes += spooled.length_bytes;
    }
  }
  TESSERA_TRY(flush_run());
  return copied;
}

/// One level's directory pages and its page index as a block to place (no bytes when every
/// page is empty).
Result<PlacedBlock> placeLevelPages(const ImageInfo& info, uint32_t level,
                                    const std::vector<TileEntry>& entries, FileAppender& appender) {
  PlacedBlock block;
  TESSERA_ASSIGN_OR_RETURN(block.bytes, writeLevelPages(info, level, entries, appender));
  block.ref.length_bytes = block.bytes.size();
  if (!block.bytes.empty()) block.ref.checksum = checksum64(block.bytes);
  return block;
}

/// Directory pages, coarse levels first like the payloads, and each level's page index.
Result<WrittenDirectory> writeDirectoryPages(std::span<const SpooledImage> images,
                                             const ArchiveEntries& entries,
                                             FileAppender& appender) {
  WrittenDirectory directory;
  directory.records.resize(images.size());
  for (uint32_t i = 0; i < images.size(); ++i) {
    const ImageInfo& info = images[i].info;
    ImageRecord& record = directory.records[i];
    record.info = info;
    record.levels.resize(info.level_count);
    for (uint32_t l = info.level_count; l-- > 0;) {
      uint64_t level_payload = 0;
      for (const TileEntry& entry : entries[i][l]) level_payload += entry.length_bytes;
      record.levels[l].payload_bytes = level_payload;
      TESSERA_ASSIGN_OR_RETURN(PlacedBlock index,
                               placeLevelPages(info, l, entries[i][l], appender));
      directory.page_indexes.push_back(std::move(index));
    }
  }
  return directory;
}

/// The metadata block: `metadata` as JSON text, checksummed, not placed yet.
Result<PlacedBlock> metadataBlock(const nlohmann::json& metadata, const std::string& name) {
  PlacedBlock block;
  std::string text = metadata.dump();
  block.bytes.assign(text.begin(), text.end());
  block.ref.length_bytes = block.bytes.size();
  block.ref.checksum = checksum64(block.bytes);
  if (block.bytes.size() > kMaxMetadataBytes)
    return fail(ErrorCode::kTooLarge, name + ": metadata exceeds 16 MiB");
  return block;
}

/// Writes the header region with the root directory and, last, the header: until those 128
/// bytes land the file does not parse as an archive. Returns the file's size.
Result<uint64_t> writeHeaderRegion(const TempFile& out, HeaderRegion& region,
                                   const std::vector<ImageRecord>& records,
                                   const BlockRef& metadata, uint64_t end_bytes) {
  std::vector<uint8_t> root = encodeRootDirectory(records);
  std::span<uint8_t> bytes = region.bytes();
  std::memcpy(bytes.data() + kHeaderBytes, root.data(), root.size());
  FileHeader header;
  header.version_minor = minorVersionFor(records);
  header.file_bytes = std::max<uint64_t>(end_bytes, kHeaderRegionBytes);
  header.image_count = uint32_t(records.size());
  header.root = {kHeaderBytes, root.size(), checksum64(root)};
  header.metadata = metadata;
  TESSERA_TRY(out.pwrite(kHeaderBytes, bytes.subspan(kHeaderBytes)));
  if (end_bytes < kHeaderRegionBytes) TESSERA_TRY(out.pwrite(0, bytes.first(kHeaderBytes)));
  std::vector<uint8_t> header_bytes = encodeHeader(header);
  TESSERA_TRY(out.pwrite(0, header_bytes));
  return header.file_bytes;
}

}  // namespace

Result<WrittenArchive> writeArchive(const TempFile& spool, uint64_t spool_bytes,
                                    std::span<const SpooledImage> images, TileOrder order,
                                    const nlohmann::json& metadata, const TempFile& out) {
  // pread, not a mapping: mapped spool pages count in the process's resident set, which would
  // then grow with the archive. Payloads the encoders spooled one after another are read in
  // one call.
  auto from_spool = [&](std::span<const RunTile> run, std::span<uint8_t> bytes) -> Result<void> {
    return forEachStoredRange(
        run, [&](size_t, size_t, uint64_t offset, size_t at, size_t length) -> Result<void> {
          TESSERA_CHECK(offset + length <= spool_bytes) << "spool entry past the spool end";
          return spool.pread(offset, bytes.subspan(at, length));
        });
  };
  return writeArchiveRuns(from_spool, images, order, metadata, out);
}

Result<WrittenArchive> writeArchive(const PayloadFetcher& fetch,
                                    std::span<const SpooledImage> images, TileOrder order,
                                    const nlohmann::json& metadata, const TempFile& out) {
  auto each_tile = [&](std::span<const RunTile> run, std::span<uint8_t> bytes) -> Result<void> {
    size_t at = 0;
    for (const RunTile& tile : run) {
      TESSERA_TRY(fetch(tile.tile, *tile.entry, bytes.subspan(at, tile.entry->length_bytes)));
      at += tile.entry->length_bytes;
    }
    return {};
  };
  return writeArchiveRuns(each_tile, images, order, metadata, out);
}

Result<WrittenArchive> writeArchiveRuns(const PayloadRunFetcher& fetch,
                                        std::span<const SpooledImage> images, TileOrder order,
                                        const nlohmann::json& metadata, const TempFile& out) {
  auto fill = [&](std::span<const RunTile> run, size_t run_bytes,
                  FileAppender& appender) -> Result<void> {
    TESSERA_TRY(appender.appendFilled(run_bytes,
                                      [&](std::span<uint8_t> bytes) { return fetch(run, bytes); }));
    return {};
  };
  return writeArchiveAppending(fill, images, order, metadata, out, AppendWrites::kInline);
}

Result<WrittenArchive> writeArchiveAppending(const PayloadRunAppender& append,
                                             std::span<const SpooledImage> images, TileOrder order,
                                             const nlohmann::json& metadata, const TempFile& out,
                                             AppendWrites writes) {
  const std::string& name = out.finalPath();
  FileAppender appender(out, kHeaderRegionBytes, writes);
  TESSERA_ASSIGN_OR_RETURN(CopiedPayloads payloads, copyPayloads(append, images, order, appender));
  TESSERA_ASSIGN_OR_RETURN(WrittenDirectory directory,
                           writeDirectoryPages(images, payloads.entries, appender));

  // Page indexes and metadata go in the header region while they fit (one read opens the
  // archive), else at the tail. The root directory's size is known before its contents.
  uint64_t root_bytes = 0;
  for (const ImageRecord& record : directory.records)
    root_bytes += kImageRecordBytes + uint64_t(record.info.level_count) * kLevelRecordBytes;
  HeaderRegion region(root_bytes);
  size_t next_index = 0;
  for (uint32_t i = 0; i < images.size(); ++i) {
    for (uint32_t l = images[i].info.level_count; l-- > 0;) {
      PlacedBlock& block = directory.page_indexes[next_index++];
      TESSERA_TRY(region.place(block, appender));
      directory.records[i].levels[l].page_index = block.ref;
    }
  }
  TESSERA_ASSIGN_OR_RETURN(PlacedBlock metadata_block, metadataBlock(metadata, name));
  TESSERA_TRY(region.place(metadata_block, appender));
  TESSERA_TRY(appender.flush());
  if (root_bytes > kHeaderRegionBytes - kHeaderBytes)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {} images need a {} byte root directory, over the {} byte "
                            "header region",
                            name, images.size(), root_bytes, kHeaderRegionBytes));

  WrittenArchive written;
  written.payload_bytes = payloads.payload_bytes;
  TESSERA_ASSIGN_OR_RETURN(
      written.file_bytes,
      writeHeaderRegion(out, region, directory.records, metadata_block.ref, appender.end()));
  return written;
}

Result<std::vector<uint8_t>> writeLevelPages(const ImageInfo& info, uint32_t level,
                                             const std::vector<TileEntry>& entries,
                                             FileAppender& appender) {
  uint32_t pages_x = pagesX(info, level), pages_y = pagesY(info, level);
  std::vector<PageRef> refs(size_t(pages_x) * pages_y);
  bool any_page = false;
  for (uint32_t py = 0; py < pages_y; ++py) {
    for (uint32_t px = 0; px < pages_x; ++px) {
      PageGeometry geometry = pageGeometry(info, level, px, py);
      std::vector<TileEntry> page_entries;
      page_entries.reserve(size_t(geometry.columns) * geometry.rows);
      bool all_empty = true;
      for (uint32_t ty = 0; ty < geometry.rows; ++ty) {
        for (uint32_t tx = 0; tx < geometry.columns; ++tx) {
          size_t slot =
              size_t(geometry.first_tile_y + ty) * info.tilesX(level) + geometry.first_tile_x + tx;
          page_entries.push_back(entries[slot]);
          all_empty &= page_entries.back().kind == TileKind::kEmpty;
        }
      }
      if (all_empty) continue;
      std::vector<uint8_t> bytes = encodeTileEntries(page_entries);
      PageRef& ref = refs[size_t(py) * pages_x + px];
      TESSERA_ASSIGN_OR_RETURN(ref.offset_bytes, appender.append(bytes));
      ref.length_bytes = bytes.size();
      ref.checksum = checksum64(bytes);
      any_page = true;
    }
  }
  if (!any_page) return std::vector<uint8_t>{};
  return encodePageIndex(refs);
}

}  // namespace tessera::detail
