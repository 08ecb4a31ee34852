#pragma once
// PMTiles version 3 (protomaps' single-file tile archive), the parts a writer needs: tile ids
// on the Hilbert curves, the directory encoding and the 127-byte header. Pure: bytes out, no
// I/O. The layout is summarised in docs/export.md.

#include <cstdint>
#include <vector>

namespace tessera::detail::pmtiles {

/// The header's fixed size, and how far a reader fetches at first: the header and the root
/// directory must lie within kRootWindowBytes.
inline constexpr uint64_t kHeaderBytes = 127;
inline constexpr uint64_t kRootWindowBytes = 16384;

/// Tile type codes of the header (byte 99).
enum class TileType : uint8_t { kUnknown = 0, kMvt = 1, kPng = 2, kJpeg = 3, kWebp = 4 };

/// The id of tile (z, x, y): the tiles of all coarser zooms counted, then the position of
/// (x, y) along the Hilbert curve of zoom z. z at most 31; x, y below 2^z.
uint64_t tileId(uint32_t z, uint32_t x, uint32_t y);

/// A directory entry: `run_length` consecutive ids from `tile_id` share one blob at `offset`
/// (from the start of the tile data); run_length 0 points at a leaf directory instead (offset
/// from the start of the leaf directories).
struct Entry {
  uint64_t tile_id = 0;
  uint64_t offset = 0;
  uint32_t length = 0;
  uint32_t run_length = 0;
};

/// A directory as stored, uncompressed: the entry count, then columns of tile id deltas,
/// run lengths, lengths and offsets (0 where an entry follows the previous one's bytes,
/// offset + 1 otherwise), each a LEB128 varint. Entries sorted by tile_id.
std::vector<uint8_t> encodeDirectory(const std::vector<Entry>& entries);

/// Section offsets and counts the header records. Bounds are the world's and the centre 0, 0
/// (the archive's images are not georeferenced).
struct Header {
  uint64_t root_offset = 0, root_bytes = 0;
  uint64_t metadata_offset = 0, metadata_bytes = 0;
  uint64_t leaves_offset = 0, leaves_bytes = 0;
  uint64_t tile_data_offset = 0, tile_data_bytes = 0;
  uint64_t addressed_tiles = 0, tile_entries = 0, tile_contents = 0;
  bool clustered = true;  ///< blobs in tile id order
  TileType tile_type = TileType::kUnknown;
  uint8_t min_zoom = 0, max_zoom = 0;
};

/// The 127 header bytes. Internal and tile compression are both "none" (1): directories are
/// stored plain and tiles are image files.
std::vector<uint8_t> encodeHeader(const Header& header);

}  // namespace tessera::detail::pmtiles
