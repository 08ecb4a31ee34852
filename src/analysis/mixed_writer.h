#pragma once
// Lays out a mixed archive (docs/format.md, "Procedural tiles"): baked payloads and instance
// pages in the clustering order (identical pages stored once), brush images and the layer
// once, directory pages with procedural entries, the procedural directory, and the header last,
// stamped as format 1.1 when any tile is procedural (else it is a plain 1.0 archive).

#include <cstdint>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/format.h>
#include <tessera/result.h>

#include "format/procedural.h"
#include "output/output_file.h"

namespace tessera::detail {

/// A tile after analysis: its baked form, its instance page (in the spool) when it could be
/// procedural, and the choice.
struct MixedTile {
  TileKind baked_kind = TileKind::kEmpty;  ///< kEmpty, kUniform or kEncoded
  uint32_t uniform_rgba = 0;
  uint64_t payload_offset = 0;  ///< spool, kEncoded
  uint32_t payload_length = 0;
  uint64_t payload_checksum = 0;
  uint64_t page_offset = 0;  ///< spool, when has_page
  uint32_t page_length = 0;
  bool has_page = false;
  bool procedural = false;  ///< the storage choice; requires has_page
};

/// A brush image or the layer, encoded with a lossless codec.
struct MixedPicture {
  std::vector<uint8_t> payload;
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t channels = 4;
  Codec codec = Codec::kZstd;
};

/// The brushes to store: only those some procedural tile draws, renumbered densely.
struct MixedBrushes {
  std::vector<ProceduralBrushRecord> brushes;  ///< stored brushes; image indexes into pictures
  std::vector<MixedPicture> pictures;
  std::optional<MixedPicture> layer;
  std::vector<int64_t> remap;  ///< database brush id -> stored id, -1 when not stored
};

struct MixedWritten {
  uint64_t file_bytes = 0;
  uint64_t baked_payload_bytes = 0;
  uint64_t page_bytes = 0;
  uint64_t brush_bytes = 0;
};

/// Writes into `out` (not committed). `tiles[level][y * tilesX + x]`.
[[nodiscard]] Result<MixedWritten> writeMixedArchive(
    const TempFile& spool, const ImageInfo& info, const std::vector<std::vector<MixedTile>>& tiles,
    const MixedBrushes& brushes, TileOrder order, const nlohmann::json& metadata,
    const TempFile& out);

}  // namespace tessera::detail
