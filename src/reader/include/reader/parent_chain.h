#pragma once
// Decoded parents for tiles coded against their parent (ptm; Marvie & Bouatouch, part I): the
// one walk that finds a tile's nearest decoded ancestor and decodes the chain from there down.
// Where decoded parents are kept is the caller's: the archive keeps recent ones for readers that
// hold no tiles (regions, verify, extract, the server), and the loader passes the streamer's
// decoded-tile cache instead, so a process keeps decoded parents in one cache, never two.

#include <cstdint>
#include <memory>

#include <tessera/archive.h>
#include <tessera/codec_scratch.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

/// Where decodeParent looks for decoded tiles and offers the ones it decodes on the way.
/// Implementations are thread-safe: loader threads and readers decode at once.
class ParentStore {
 public:
  virtual ~ParentStore() = default;
  /// The stored tile `id` decoded (storedTileSidePx() square, the image's channels), unchanged
  /// for as long as the returned handle lives; null when the store does not hold it.
  virtual std::shared_ptr<const Image> find(const TileId& id) = 0;
  /// A tile decodeParent read, verified and decoded; the store may keep it or not.
  virtual void offer(const TileId& id, const std::shared_ptr<const Image>& texels) = 0;
};

/// Payload reads made for a parent chain, for callers that account for their I/O.
struct ChainReads {
  uint32_t reads = 0;       ///< payload reads, failed ones included
  uint64_t bytes_read = 0;  ///< bytes of the reads that succeeded
};

/// True when `id` decodes only against its decoded parent: an encoded tile of a parent-coded
/// codec below its image's coarsest level.
bool codedAgainstParent(const Archive& archive, const TileId& id, const TileEntry& entry);

/// The decoded parent of `tile`, which must be below its image's coarsest level: `store`'s
/// when it holds it, else read, verified and decoded from the nearest ancestor `store` holds
/// (or the nearest that needs no parent) down, each tile offered to `store`. Counts the
/// payload reads in `reads` when not null. A parent or ancestor that is missing, corrupt or
/// undecodable fails with its error, prefixed "<tile>: its parent cannot be decoded: ", so the
/// message names both tiles; no tile is ever decoded against anything but its own verified
/// parent. `scratch` may be null.
[[nodiscard]] Result<std::shared_ptr<const Image>> decodeParent(const Archive& archive,
                                                                const TileId& tile,
                                                                ParentStore& store,
                                                                CodecScratch* scratch,
                                                                ChainReads* reads = nullptr);

}  // namespace tessera::detail
