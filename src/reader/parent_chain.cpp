#include "reader/parent_chain.h"

#include <vector>

#include <fmt/format.h>

#include <tessera/check.h>

namespace tessera::detail {
namespace {

/// An ancestor to decode, with its directory entry.
struct ChainLink {
  TileId id;
  TileEntry entry;
};

/// What the walk up from a tile found: the nearest ancestor the store holds (null when none),
/// and the ancestors below it to decode, finest first.
struct ChainStart {
  std::shared_ptr<const Image> held;
  std::vector<ChainLink> to_decode;
};

Result<ChainStart> walkUp(const Archive& archive, const TileId& tile, ParentStore& store) {
  ChainStart start;
  for (TileId id = Archive::parentTile(tile);; id = Archive::parentTile(id)) {
    if ((start.held = store.find(id))) break;
    TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(id));
    start.to_decode.push_back({id, entry});
    if (!codedAgainstParent(archive, id, entry)) break;
  }
  return start;
}

/// Reads (for an encoded tile), verifies and decodes one link against `parent` (null when it
/// needs none).
Result<std::shared_ptr<const Image>> decodeLink(const Archive& archive, const ChainLink& link,
                                                const Image* parent, CodecScratch* scratch,
                                                ChainReads& reads) {
  std::vector<uint8_t> payload;
  if (link.entry.hasPayload()) {
    ++reads.reads;
    TESSERA_ASSIGN_OR_RETURN(payload, archive.readPayload(link.id, link.entry));
    reads.bytes_read += payload.size();
  }
  auto decoded = std::make_shared<Image>();
  TESSERA_TRY(parent
                  ? archive.decodeTileInto(link.id, link.entry, payload, *decoded, *parent, scratch)
                  : archive.decodeTileInto(link.id, link.entry, payload, *decoded, scratch));
  return std::shared_ptr<const Image>(std::move(decoded));
}

Result<std::shared_ptr<const Image>> decodeChain(const Archive& archive, const TileId& tile,
                                                 ParentStore& store, CodecScratch* scratch,
                                                 ChainReads& reads) {
  TESSERA_ASSIGN_OR_RETURN(ChainStart start, walkUp(archive, tile, store));
  std::shared_ptr<const Image> parent = std::move(start.held);
  for (auto it = start.to_decode.rbegin(); it != start.to_decode.rend(); ++it) {
    TESSERA_ASSIGN_OR_RETURN(parent, decodeLink(archive, *it, parent.get(), scratch, reads));
    store.offer(it->id, parent);
  }
  return parent;
}

}  // namespace

bool codedAgainstParent(const Archive& archive, const TileId& id, const TileEntry& entry) {
  return entry.kind == TileKind::kEncoded && codecNeedsParent(entry.codec) &&
         id.image < archive.images().size() &&
         id.level + 1 < archive.images()[id.image].level_count;
}

Result<std::shared_ptr<const Image>> decodeParent(const Archive& archive, const TileId& tile,
                                                  ParentStore& store, CodecScratch* scratch,
                                                  ChainReads* reads) {
  TESSERA_CHECK(tile.image < archive.images().size() &&
                tile.level + 1 < archive.images()[tile.image].level_count)
      << archive.tileName(tile) << " has no parent";
  ChainReads counted;
  Result<std::shared_ptr<const Image>> parent =
      decodeChain(archive, tile, store, scratch, reads ? *reads : counted);
  if (!parent)
    return fail(parent.error().code, fmt::format("{}: its parent cannot be decoded: {}",
                                                 archive.tileName(tile), parent.error().message));
  return parent;
}

}  // namespace tessera::detail
