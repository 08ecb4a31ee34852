#pragma once
// The tile data of a PMTiles file: blobs appended in tile-id order, each distinct blob stored
// once. Payloads copied from the archive are queued while they lie back to back there, and a
// run of them costs one read, straight into the output buffer, checksums verified in place.

#include <cstdint>
#include <map>
#include <span>
#include <utility>
#include <vector>

#include <tessera/archive.h>
#include <tessera/result.h>

#include "output/file_appender.h"
#include "output/output_file.h"

namespace tessera::detail {

/// Where a tile's blob lies.
struct PlacedBlob {
  uint64_t offset_bytes = 0;  ///< from the start of the tile data
  uint32_t length_bytes = 0;
  bool fresh = false;  ///< the bytes were stored now, not shared with an earlier tile
};

/// Appends the tile blobs of one PMTiles file from `start`. Owned by one thread; the archive and
/// the TempFile must outlive it. Bytes are in the file only after flush().
class TileBlobs {
 public:
  TileBlobs(const Archive& archive, const TempFile& out, uint64_t start)
      : archive_(archive), out_(out), appender_(out, start), start_(start) {}

  /// The stored payload of `tile` (entry.hasPayload()) as it is. A mismatch with the entry's
  /// checksum fails (naming the tile) here or at a later call, whichever writes the run.
  [[nodiscard]] Result<PlacedBlob> copy(const TileId& tile, const TileEntry& entry);
  /// `bytes`, a picture made for the tile.
  [[nodiscard]] Result<PlacedBlob> put(std::span<const uint8_t> bytes);
  /// Writes the queued run and the buffer. The appender may be used directly after it.
  [[nodiscard]] Result<void> flush();
  FileAppender& appender() { return appender_; }

 private:
  struct Stored {
    uint64_t offset_bytes;          ///< from the start of the tile data
    uint64_t archive_offset_bytes;  ///< where a copied payload came from; kNoSource else
  };
  struct Pending {
    TileId tile;
    TileEntry entry;
  };
  static constexpr uint64_t kNoSource = ~uint64_t(0);

  Result<void> writeRun();
  // An earlier blob of this checksum and length holding the same bytes, if any.
  Result<std::optional<uint64_t>> findEqual(uint64_t checksum, std::span<const uint8_t> bytes);
  uint64_t nextOffset() const { return appender_.end() + run_bytes_ - start_; }

  const Archive& archive_;
  const TempFile& out_;
  FileAppender appender_;
  uint64_t start_;
  std::vector<Pending> run_;  ///< payloads back to back in the archive, not yet read
  uint64_t run_bytes_ = 0;
  std::multimap<std::pair<uint64_t, uint32_t>, Stored> seen_;  ///< by checksum and length
};

}  // namespace tessera::detail
