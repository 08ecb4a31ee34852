#include "archive_writer.h"

#include <cstring>

#include <fmt/format.h>

#include <tessera/archive.h>

#include "format/checksum.h"
#include "format/directory.h"
#include "format/header.h"
#include "format/tile_order.h"

namespace tessera::detail {

namespace {

constexpr size_t kWriteBufferBytes = 8u << 20;

// Appends bytes at the end of the output through a large buffer, so thousands of small
// payloads cost a few large writes.
class Appender {
 public:
  Appender(const TempFile& out, uint64_t start) : out_(out), end_(start), flushed_(start) {
    buffer_.reserve(kWriteBufferBytes);
  }
  Result<uint64_t> append(std::span<const uint8_t> bytes) {
    uint64_t offset = end_;
    if (buffer_.size() + bytes.size() > kWriteBufferBytes) TESSERA_TRY(flush());
    if (bytes.size() > kWriteBufferBytes) {
      TESSERA_TRY(out_.pwrite(flushed_, bytes));
      flushed_ += bytes.size();
    } else {
      buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
    }
    end_ += bytes.size();
    return offset;
  }
  Result<void> flush() {
    if (buffer_.empty()) return {};
    TESSERA_TRY(out_.pwrite(flushed_, buffer_));
    flushed_ += buffer_.size();
    buffer_.clear();
    return {};
  }
  uint64_t end() const { return end_; }

 private:
  const TempFile& out_;
  uint64_t end_;
  uint64_t flushed_;
  std::vector<uint8_t> buffer_;
};

struct PlacedBlock {
  BlockRef ref;
  std::vector<uint8_t> bytes;
};

}  // namespace

Result<WrittenArchive> writeArchive(const TempFile& spool, uint64_t spool_bytes,
                                    std::span<const SpooledImage> images, TileOrder order,
                                    const nlohmann::json& metadata, const TempFile& out) {
  const std::string& name = out.finalPath();
  // Payloads are copied from the spool with pread, not through a mapping: mapped spool pages
  // count in the process's resident set, which would then grow with the archive.
  std::vector<uint8_t> payload;

  // Payloads, clustered. Entries are copied so the caller's spool offsets stay intact.
  std::vector<std::vector<std::vector<TileEntry>>> final_entries(images.size());
  Appender appender(out, kHeaderRegionBytes);
  WrittenArchive written;
  for (uint32_t i = 0; i < images.size(); ++i) {
    const SpooledImage& image = images[i];
    auto& levels = final_entries[i];
    levels.resize(image.entries.size());
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
    for (const TileId& tile : tileOrder(image.info, i, order)) {
      size_t slot = size_t(tile.y) * image.info.tilesX(tile.level) + tile.x;
      const SpoolEntry& spooled = image.entries[tile.level][slot];
      if (spooled.kind != TileKind::kEncoded) continue;
      TESSERA_CHECK(spooled.spool_offset + spooled.length_bytes <= spool_bytes)
          << "spool entry past the spool end";
      payload.resize(spooled.length_bytes);
      TESSERA_TRY(spool.pread(spooled.spool_offset, payload));
      TESSERA_ASSIGN_OR_RETURN(levels[tile.level][slot].offset_bytes, appender.append(payload));
      written.payload_bytes += spooled.length_bytes;
    }
  }

  // Directory pages, coarse levels first like the payloads, and the page indexes.
  std::vector<ImageRecord> records(images.size());
  std::vector<PlacedBlock> page_indexes;
  for (uint32_t i = 0; i < images.size(); ++i) {
    const ImageInfo& info = images[i].info;
    records[i].info = info;
    records[i].levels.resize(info.level_count);
    for (uint32_t l = info.level_count; l-- > 0;) {
      uint32_t pages_x = pagesX(info, l), pages_y = pagesY(info, l);
      std::vector<PageRef> refs(size_t(pages_x) * pages_y);
      bool any_page = false;
      for (uint32_t py = 0; py < pages_y; ++py) {
        for (uint32_t px = 0; px < pages_x; ++px) {
          PageGeometry geometry = pageGeometry(info, l, px, py);
          std::vector<TileEntry> page_entries;
          page_entries.reserve(size_t(geometry.columns) * geometry.rows);
          bool all_empty = true;
          for (uint32_t ty = 0; ty < geometry.rows; ++ty) {
            for (uint32_t tx = 0; tx < geometry.columns; ++tx) {
              size_t slot =
                  size_t(geometry.first_tile_y + ty) * info.tilesX(l) + geometry.first_tile_x + tx;
              page_entries.push_back(final_entries[i][l][slot]);
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
      uint64_t level_payload = 0;
      for (const TileEntry& entry : final_entries[i][l]) level_payload += entry.length_bytes;
      records[i].levels[l].payload_bytes = level_payload;
      if (any_page) {
        PlacedBlock block;
        block.bytes = encodePageIndex(refs);
        block.ref.length_bytes = block.bytes.size();
        block.ref.checksum = checksum64(block.bytes);
        page_indexes.push_back(std::move(block));
      } else {
        page_indexes.push_back({});
      }
    }
  }

  // Place page indexes and metadata in the header region while they fit (one read opens the
  // archive), else at the tail. The root directory's size is known before its contents.
  uint64_t root_bytes = 0;
  for (const ImageRecord& record : records)
    root_bytes += kImageRecordBytes + uint64_t(record.info.level_count) * kLevelRecordBytes;
  std::vector<uint8_t> region(kHeaderRegionBytes, 0);
  uint64_t region_used = kHeaderBytes + root_bytes;
  auto place = [&](PlacedBlock& block) -> Result<void> {
    if (block.bytes.empty()) return {};
    if (region_used + block.bytes.size() <= kHeaderRegionBytes) {
      block.ref.offset_bytes = region_used;
      std::memcpy(region.data() + region_used, block.bytes.data(), block.bytes.size());
      region_used += block.bytes.size();
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(block.ref.offset_bytes, appender.append(block.bytes));
    return {};
  };
  size_t next_index = 0;
  for (uint32_t i = 0; i < images.size(); ++i) {
    for (uint32_t l = images[i].info.level_count; l-- > 0;) {
      PlacedBlock& block = page_indexes[next_index++];
      TESSERA_TRY(place(block));
      records[i].levels[l].page_index = block.ref;
    }
  }
  PlacedBlock metadata_block;
  std::string metadata_text = metadata.dump();
  metadata_block.bytes.assign(metadata_text.begin(), metadata_text.end());
  metadata_block.ref.length_bytes = metadata_block.bytes.size();
  metadata_block.ref.checksum = checksum64(metadata_block.bytes);
  if (metadata_block.bytes.size() > kMaxMetadataBytes)
    return fail(ErrorCode::kTooLarge, name + ": metadata exceeds 16 MiB");
  TESSERA_TRY(place(metadata_block));
  TESSERA_TRY(appender.flush());

  if (root_bytes > kHeaderRegionBytes - kHeaderBytes)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {} images need a {} byte root directory, over the {} byte "
                            "header region",
                            name, images.size(), root_bytes, kHeaderRegionBytes));
  std::vector<uint8_t> root = encodeRootDirectory(records);
  std::memcpy(region.data() + kHeaderBytes, root.data(), root.size());

  FileHeader header;
  header.file_bytes = std::max<uint64_t>(appender.end(), kHeaderRegionBytes);
  header.image_count = uint32_t(images.size());
  header.root = {kHeaderBytes, root.size(), checksum64(root)};
  header.metadata = metadata_block.ref;
  // The region without the header first, the header last: until those 128 bytes land the
  // file does not parse as an archive.
  TESSERA_TRY(out.pwrite(kHeaderBytes, std::span(region).subspan(kHeaderBytes)));
  if (appender.end() < kHeaderRegionBytes)
    TESSERA_TRY(out.pwrite(0, std::span(region).first(kHeaderBytes)));
  std::vector<uint8_t> header_bytes = encodeHeader(header);
  TESSERA_TRY(out.pwrite(0, header_bytes));
  written.file_bytes = header.file_bytes;
  return written;
}

}  // namespace tessera::detail
