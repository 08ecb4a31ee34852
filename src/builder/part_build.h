#pragma once
// The archive a part of a split build writes, and what the merge reads back from it
// (docs/builder.md, "Split and merge"). Image 0 is the whole image's geometry with the part's
// tiles below level M filled in (the others empty); image 1, when the part owns rows, holds
// the part's exact level-M rows, losslessly, from which the merge computes levels M and up.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/format.h>
#include <tessera/result.h>

#include "archive_writer.h"
#include "part_plan.h"

namespace tessera::detail {

/// Name of image 1 of a part archive.
inline constexpr const char* kPartRowsImageName = "split-level-rows";

/// Where a part sits in the split.
struct PartLayout {
  const ImageInfo& info;  ///< the whole image
  PartPlan plan;
  uint32_t first_row = 0, end_row = 0;  ///< the part's level-0 rows
  uint32_t window_first_row = 0;        ///< level-0 row 0 of the window archive
};

/// A part's stored entry as the writer takes it, spool_offset being the payload's offset in
/// the part's file.
SpoolEntry spoolEntryOf(const TileEntry& entry);

/// The clustering order `archive_metadata` (a build's metadata) records. A part stores its
/// tiles in that order too, so each of its stretches of the output is one run in its file.
TileOrder buildOrderOf(const nlohmann::json& archive_metadata);

/// The image holding `rows` exact rows of level `plan.merge_level` of `info`.
ImageInfo partRowsInfo(const ImageInfo& info, uint32_t merge_level, uint32_t rows);

/// Writes the part archive to `output` atomically: tiles of levels below M copied from
/// `window` (null when the part owns none), `level_rows` (exact level-M rows, tightly packed)
/// as image 1, `part` as the "split_part" metadata. Returns the file's size.
[[nodiscard]] Result<uint64_t> writePartArchive(const PartLayout& layout, const Archive* window,
                                                const std::vector<uint8_t>& level_rows,
                                                const nlohmann::json& part,
                                                const std::string& output);

}  // namespace tessera::detail
