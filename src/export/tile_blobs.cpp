#include "tile_blobs.h"

#include <algorithm>

#include "format/checksum.h"

namespace tessera::detail {

Result<PlacedBlob> TileBlobs::copy(const TileId& tile, const TileEntry& entry) {
  const auto key = std::pair{entry.checksum, entry.length_bytes};
  const auto [first, last] = seen_.equal_range(key);
  // The same payload (the archive shares it between tiles) needs no comparison.
  for (auto it = first; it != last; ++it)
    if (it->second.archive_offset_bytes == entry.offset_bytes)
      return PlacedBlob{it->second.offset_bytes, entry.length_bytes, false};
  if (first != last) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload, archive_.readPayload(tile, entry));
    TESSERA_ASSIGN_OR_RETURN(std::optional<uint64_t> equal, findEqual(entry.checksum, payload));
    if (equal) return PlacedBlob{*equal, entry.length_bytes, false};
  }
  if (!run_.empty()) {
    const TileEntry& previous = run_.back().entry;
    const bool follows = previous.offset_bytes + previous.length_bytes == entry.offset_bytes;
    if (!follows || run_bytes_ + entry.length_bytes > FileAppender::kBufferBytes)
      TESSERA_TRY(writeRun());
  }
  const uint64_t offset = nextOffset();
  run_.push_back({tile, entry});
  run_bytes_ += entry.length_bytes;
  seen_.insert({key, {offset, entry.offset_bytes}});
  return PlacedBlob{offset, entry.length_bytes, true};
}

Result<PlacedBlob> TileBlobs::put(std::span<const uint8_t> bytes) {
  const uint64_t checksum = checksum64(bytes);
  const auto length = uint32_t(bytes.size());
  TESSERA_ASSIGN_OR_RETURN(std::optional<uint64_t> equal, findEqual(checksum, bytes));
  if (equal) return PlacedBlob{*equal, length, false};
  TESSERA_TRY(writeRun());
  TESSERA_ASSIGN_OR_RETURN(const uint64_t at, appender_.append(bytes));
  seen_.insert({{checksum, length}, {at - start_, kNoSource}});
  return PlacedBlob{at - start_, length, true};
}

Result<void> TileBlobs::flush() {
  TESSERA_TRY(writeRun());
  return appender_.flush();
}

Result<void> TileBlobs::writeRun() {
  if (run_.empty()) return {};
  const uint64_t from = run_.front().entry.offset_bytes;
  Result<uint64_t> written =
      appender_.appendFilled(run_bytes_, [&](std::span<uint8_t> place) -> Result<void> {
        TESSERA_TRY(archive_.source().read(from, place));
        size_t at = 0;
        for (const Pending& pending : run_) {
          const uint32_t length = pending.entry.length_bytes;
          TESSERA_TRY(
              archive_.verifyPayload(pending.tile, pending.entry, place.subspan(at, length)));
          at += length;
        }
        return {};
      });
  run_.clear();
  run_bytes_ = 0;
  if (!written) return forwardError(written);
  return {};
}

Result<std::optional<uint64_t>> TileBlobs::findEqual(uint64_t checksum,
                                                     std::span<const uint8_t> bytes) {
  const auto [first, last] = seen_.equal_range({checksum, uint32_t(bytes.size())});
  if (first == last) return std::optional<uint64_t>{};
  // Equal checksums are confirmed against the bytes stored, before two tiles share them.
  TESSERA_TRY(flush());
  std::vector<uint8_t> stored(bytes.size());
  for (auto it = first; it != last; ++it) {
    TESSERA_TRY(out_.pread(start_ + it->second.offset_bytes, stored));
    if (std::equal(stored.begin(), stored.end(), bytes.begin(), bytes.end()))
      return std::optional<uint64_t>{it->second.offset_bytes};
  }
  return std::optional<uint64_t>{};
}

}  // namespace tessera::detail
