#pragma once
/// \file
/// Reading archives: open over any ByteSource, list images and levels, read and decode tiles
/// with checksum verification, read any rectangle of any level as RGBA.

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <tessera/byte_source.h>
#include <tessera/codec_scratch.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera {

class ProceduralTiles;
class TileCompositor;

/// What `Archive::verify` found.
struct VerifyReport {
  uint64_t tiles_checked = 0;     ///< directory entries examined
  uint64_t payloads_checked = 0;  ///< encoded payloads read and checksummed
  uint64_t payload_bytes = 0;
  uint64_t pages_checked = 0;
  uint64_t fault_count = 0;         ///< every fault found
  std::vector<std::string> faults;  ///< the first kMaxReportedFaults messages, in file order
  static constexpr size_t kMaxReportedFaults = 100;
  bool ok() const { return fault_count == 0; }
};

/// A pixel rectangle at one level: [x, x + width) x [y, y + height).
struct PixelRect {
  int64_t x = 0;
  int64_t y = 0;
  uint32_t width = 0;
  uint32_t height = 0;
};

/// An opened archive. Thread-safe: immutable after `open`, except for an internal cache of
/// directory pages guarded by its own mutex. Every method may be called from any thread.
class Archive {
 public:
  /// Reads the header region (one read of the first 16 KiB, one HTTP request later), checks
  /// magic, version, checksums and structural bounds, and parses the root directory and
  /// metadata. Directory pages are read on demand. Fails naming `source->name()` and the
  /// problem: not an archive, newer major version, truncated file, checksum mismatch, field
  /// out of bounds.
  [[nodiscard]] static Result<std::shared_ptr<Archive>> open(std::shared_ptr<ByteSource> source);
  /// Opens a local file (openFileSource, pread-based). For a path or an http(s):// URL, see
  /// openArchive in tessera/open.h.
  [[nodiscard]] static Result<std::shared_ptr<Archive>> openFile(const std::string& path);

  ~Archive();
  Archive(const Archive&) = delete;
  Archive& operator=(const Archive&) = delete;

  const std::string& name() const;
  /// How errors name a tile: "<archive>: tile (level,x,y)", with the image when there are
  /// several.
  std::string tileName(const TileId& tile) const;
  const std::vector<ImageInfo>& images() const;
  /// The archive's metadata block as stored: a UTF-8 JSON object (docs/format.md, "Metadata"),
  /// "{}" when the file has none. Checked at open to be one JSON object.
  const std::string& metadataJson() const;
  /// Total file size in bytes as recorded in the header.
  uint64_t fileBytes() const;
  const ByteSource& source() const;

  /// The directory entry of a tile, reading and verifying its directory page on first use.
  /// An address outside the image's levels or tile grid is kInvalidArgument.
  [[nodiscard]] Result<TileEntry> tileEntry(const TileId& tile) const;
  /// The directory entry of a tile if its page is in memory, without any read: for a caller
  /// that must not wait (the render thread sizing its requests). Empty when the page is not
  /// loaded yet or the address is outside the image.
  std::optional<TileEntry> tileEntryIfCached(const TileId& tile) const;

  /// Reads a tile's payload and verifies its checksum: an encoded payload, or a procedural
  /// tile's instance page. Only for tiles whose entry hasPayload().
  [[nodiscard]] Result<std::vector<uint8_t>> readPayload(const TileId& tile,
                                                         const TileEntry& entry) const;

  /// Checks `payload` (read by the caller, e.g. within a merged range) against the entry's
  /// length and checksum; the error names the tile and the offset.
  [[nodiscard]] Result<void> verifyPayload(const TileId& tile, const TileEntry& entry,
                                           std::span<const uint8_t> payload) const;

  /// Decodes a verified payload (or expands an empty/uniform entry) into a stored tile:
  /// storedTileSidePx() square with borders, the image's channel count. `scratch` may be null.
  /// A tile of a codec coded against its parent (ptm) below the coarsest level first obtains
  /// its decoded parent: from a small internal cache of recently decoded parents, or by
  /// reading it (recursively, coarsest ancestor first). A parent that is missing, corrupt or
  /// undecodable fails the child, naming both tiles; no child is ever decoded against a
  /// parent other than its own verified one.
  [[nodiscard]] Result<Image> decodeTile(const TileId& tile, const TileEntry& entry,
                                         std::span<const uint8_t> payload,
                                         CodecScratch* scratch = nullptr) const;
  /// The same into `out`, reusing its buffer: when `out.texels` already holds a stored tile's
  /// bytes nothing is allocated, zeroed or page-faulted (the streamer recycles evicted tiles'
  /// buffers this way). Every texel is written, whatever `out` held before.
  [[nodiscard]] Result<void> decodeTileInto(const TileId& tile, const TileEntry& entry,
                                            std::span<const uint8_t> payload, Image& out,
                                            CodecScratch* scratch = nullptr) const;

  /// The same with the parent's decoded stored tile supplied by the caller (a loader that
  /// decodes coarse to fine): `parent` must be what decodeTile returned for
  /// `parentTile(tile)`. For codecs that do not use a parent, or at the coarsest level,
  /// `parent` is ignored. Fails (kInvalidArgument) when `parent` has the wrong geometry.
  [[nodiscard]] Result<void> decodeTileInto(const TileId& tile, const TileEntry& entry,
                                            std::span<const uint8_t> payload, Image& out,
                                            const Image& parent,
                                            CodecScratch* scratch = nullptr) const;

  /// The tile one level coarser whose quarter `tile` refines. `tile.level + 1` must be below
  /// the image's level_count.
  static TileId parentTile(const TileId& tile) {
    return {tile.image, tile.level + 1, tile.x / 2, tile.y / 2};
  }

  /// tileEntry + readPayload + decodeTile.
  [[nodiscard]] Result<Image> readTile(const TileId& tile, CodecScratch* scratch = nullptr) const;

  /// The archive's procedural side (format 1.1): its brush set, read, checksummed and prepared
  /// on the first call (later calls return it at no cost). kNotFound when the archive has no
  /// procedural directory; a damaged brush block is kCorrupt naming it, and is retried by the
  /// next call. decodeTile composites procedural tiles through it.
  [[nodiscard]] Result<std::shared_ptr<const ProceduralTiles>> procedural() const;
  /// Composites procedural tiles with `compositor` (for example on the GPU) instead of the CPU
  /// compositor; null returns to the CPU. Thread-safe: a tile decoded while it changes uses
  /// the old or the new one.
  void setTileCompositor(std::shared_ptr<TileCompositor> compositor);
  std::shared_ptr<TileCompositor> tileCompositor() const;
  /// Reads `rect` of `level` of `image` into RGBA (gray replicated, alpha 255 when absent).
  /// Texels outside the level read as transparent black. The rectangle may be at most
  /// 16384 x 16384 px (kTooLarge beyond).
  [[nodiscard]] Result<Image> readRegionRgba(uint32_t image, uint32_t level,
                                             const PixelRect& rect) const;

  /// Same, in the image's own channel count and sample type (no RGBA expansion); outside
  /// texels are zero. A region of many tiles (16 or more) is decoded by up to one thread per
  /// core, started and joined within the call; a damaged tile fails the call naming the first
  /// one in row-major order. readRegionRgba refuses u16 and f32 images (kUnsupported): their
  /// samples need a display window to become 8-bit.
  [[nodiscard]] Result<Image> readRegion(uint32_t image, uint32_t level,
                                         const PixelRect& rect) const;

  /// Checks every checksum and structural invariant: page indexes, pages, payload checksums,
  /// that every payload decodes, that blocks lie inside the file and no two overlap. In a
  /// format 1.1 archive with procedural tiles, also the brush images and height layer
  /// (checksums, decoding), and every instance page (checksum, structure, brush references;
  /// composited when `decode_payloads`); a page shared by several tiles is checked once. Keeps
  /// going after a fault. `on_progress(done, total)` is called per level when set.
  VerifyReport verify(bool decode_payloads = true,
                      const std::function<void(uint64_t, uint64_t)>& on_progress = {}) const;

  struct Impl;

 private:
  explicit Archive(std::unique_ptr<Impl> impl);
  Result<void> decodeWithParent(const TileId& tile, const TileEntry& entry,
                                std::span<const uint8_t> payload, Image& out, const Image* parent,
                                CodecScratch* scratch) const;
  Result<std::shared_ptr<const Image>> decodedParent(const TileId& tile,
                                                     CodecScratch* scratch) const;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
