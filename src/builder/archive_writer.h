#pragma once
// Lays out a finished build as an archive: payloads copied from the spool in the clustering
// order, then directory pages, page indexes and metadata, then the header, written last
// (docs/format.md, "Writing").

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/format.h>
#include <tessera/result.h>

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

}  // namespace tessera::detail
