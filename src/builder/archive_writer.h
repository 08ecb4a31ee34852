#pragma once
// Lays out a finished build as an archive: payloads copied from the spool in the clustering
// order, then directory pages, page indexes and metadata, then the header, written last
// (docs/format.md, "Writing").

#include <cstdint>
#include <functional>
#include <span>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/format.h>
#include <tessera/result.h>

#include "output/file_appender.h"
#include "output/output_file.h"

namespace tessera::detail {

/// A tile as the encoders left it: its payload lives in the spool until the layout pass.
struct SpoolEntry {
  uint64_t spool_offset = 0;  ///< valid for kEncoded
  uint32_t length_bytes = 0;  ///< kEncoded payload length
  TileKind kind = TileKind::kEmpty;
  Codec codec = Codec::kRaw;
  uint32_t uniform_rgba = 0;
  uint64_t checksum = 0;
};

/// One image's pyramid: entries[level][y * tilesX(level) + x].
struct SpooledImage {
  ImageInfo info;
  std::vector<std::vector<SpoolEntry>> entries;
};

/// What the layout pass wrote.
struct WrittenArchive {
  uint64_t file_bytes = 0;
  uint64_t payload_bytes = 0;
};

/// Writes the archive into `out` (not yet committed). `spool` holds `spool_bytes` of payloads.
/// `metadata` is stored as the archive's JSON metadata.
[[nodiscard]] Result<WrittenArchive> writeArchive(const TempFile& spool, uint64_t spool_bytes,
                                                  std::span<const SpooledImage> images,
                                                  TileOrder order, const nlohmann::json& metadata,
                                                  const TempFile& out);

/// Fills `payload` (sized to the entry's length) with the payload of `tile`, an encoded entry:
/// where it comes from is the caller's (a spool, the parts of a split build).
using PayloadFetcher = std::function<Result<void>(const TileId& tile, const SpoolEntry& entry,
                                                  std::span<uint8_t> payload)>;

/// writeArchive with payloads from `fetch`, called once per encoded tile in the clustering
/// order.
[[nodiscard]] Result<WrittenArchive> writeArchive(const PayloadFetcher& fetch,
                                                  std::span<const SpooledImage> images,
                                                  TileOrder order, const nlohmann::json& metadata,
                                                  const TempFile& out);

/// An encoded tile of a run of consecutive payloads in the clustering order.
struct RunTile {
  TileId tile;
  const SpoolEntry* entry = nullptr;
};

/// Fills `bytes` with the payloads of `run`, back to back in order (each its entry's length):
/// `bytes` lies in the writer's buffer, so a fetcher that reads a run of payloads stored
/// together in one call moves each byte once on the way in.
using PayloadRunFetcher =
    std::function<Result<void>(std::span<const RunTile> run, std::span<uint8_t> bytes)>;

/// A run handed to a PayloadRunFetcher holds at most this many bytes (or one larger payload).
inline constexpr size_t kPayloadRunBytes = 1u << 20;

/// Calls `read(first, end, offset, at, length)` for each stretch run[first, end) of the run
/// whose payloads lie back to back in their store (spool_offset of each the end of the
/// previous): `length` bytes from `offset` there, at byte `at` of the run's bytes. A run's
/// payloads from several stores (parts) are split with `same_store(a, b)`.
template <typename Read, typename SameStore>
Result<void> forEachStoredRange(std::span<const RunTile> run, Read&& read, SameStore&& same_store) {
  size_t at = 0;
  for (size_t first = 0; first < run.size();) {
    const uint64_t offset = run[first].entry->spool_offset;
    size_t length = run[first].entry->length_bytes;
    size_t end = first + 1;
    while (end < run.size() && run[end].entry->spool_offset == offset + length &&
           same_store(run[end - 1], run[end]))
      length += run[end++].entry->length_bytes;
    TESSERA_TRY(read(first, end, offset, at, length));
    at += length;
    first = end;
  }
  return {};
}

template <typename Read>
Result<void> forEachStoredRange(std::span<const RunTile> run, Read&& read) {
  return forEachStoredRange(run, std::forward<Read>(read),
                            [](const RunTile&, const RunTile&) { return true; });
}

/// writeArchive with payloads from `fetch`, called for runs of encoded tiles in the
/// clustering order.
[[nodiscard]] Result<WrittenArchive> writeArchiveRuns(const PayloadRunFetcher& fetch,
                                                      std::span<const SpooledImage> images,
                                                      TileOrder order,
                                                      const nlohmann::json& metadata,
                                                      const TempFile& out);

/// Appends the payloads of `run` (`run_bytes` in all, back to back in order) to `appender` by
/// any means: filled into its buffer (appendFilled) or appended where they lie (appendOwned).
using PayloadRunAppender = std::function<Result<void>(std::span<const RunTile> run,
                                                      size_t run_bytes, FileAppender& appender)>;

/// writeArchiveRuns with each run placed by `append`, through an appender whose full buffers
/// are written as `writes` says (kBackground: by a second thread while the next is filled).
[[nodiscard]] Result<WrittenArchive> writeArchiveAppending(
    const PayloadRunAppender& append, std::span<const SpooledImage> images, TileOrder order,
    const nlohmann::json& metadata, const TempFile& out, AppendWrites writes);

}  // namespace tessera::detail
