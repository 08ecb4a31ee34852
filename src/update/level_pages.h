#pragma once
// Rewriting the directory of one level after some of its tiles changed: only the pages that
// hold a changed tile, and the level's page index, are appended (docs/update.md).

#include <cstdint>
#include <map>

#include <tessera/format.h>
#include <tessera/result.h>

#include "archive_tail.h"

namespace tessera::detail {

/// Changed entries of one level by tile index (y * tilesX + x); payloads already appended.
using LevelChanges = std::map<uint64_t, TileEntry>;

/// Appends the pages of `level` of `image` that hold a tile of `changes` (with the committed
/// entries elsewhere) and a new page index, and updates the level record in `tail`: its page
/// index and payload total. Replaced payloads, pages and the old index count as dead bytes.
/// An image appended to `tail.records()` with a zero level record starts with every tile empty.
[[nodiscard]] Result<void> rewriteLevel(ArchiveTail& tail, uint32_t image, uint32_t level,
                                        const LevelChanges& changes);

}  // namespace tessera::detail
