#pragma once
// Directory pages of one level, as every archive writer lays them out (docs/format.md,
// "Directory pages"): shared by the image builder and the mixed-archive writer.

#include <cstdint>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

#include "output/file_appender.h"

namespace tessera::detail {

/// Appends the non-empty directory pages of `level` (its entries in row-major slot order) and
/// returns the level's page index bytes; empty when every page is empty.
[[nodiscard]] Result<std::vector<uint8_t>> writeLevelPages(const ImageInfo& info, uint32_t level,
                                                           const std::vector<TileEntry>& entries,
                                                           FileAppender& appender);

}  // namespace tessera::detail
