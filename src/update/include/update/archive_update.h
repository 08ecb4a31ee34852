#pragma once
// Changing an archive in place (docs/update.md): new payloads, directory pages, page indexes,
// root directory and metadata are appended after the committed bytes and a new header is
// written last, so a crash at any point leaves the previous version readable and readers that
// opened it keep reading it (docs/format.md, "Appended versions").

#include <cstdint>
#include <string>

#include <tessera/build.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

/// What one committed update wrote.
struct UpdateReport {
  uint64_t version = 0;          ///< the archive's version after the update (1 = as built)
  uint64_t bytes_written = 0;    ///< appended bytes plus the rewritten header
  uint64_t dead_bytes = 0;       ///< bytes no version-current block references, in total
  uint64_t tiles_rewritten = 0;  ///< tiles re-encoded, every level together
  uint64_t file_bytes = 0;       ///< the file's committed size after the update
};

/// Replaces the texels of image `image`'s level 0 at [x, x + patch.width) x [y, y +
/// patch.height) with `patch` and recomputes every tile whose texels (borders included)
/// change, at every level, from the stored neighbouring tiles. With a lossless codec the
/// result equals, texel for texel, a build from the patched source. Fails without changing the
/// file: `path` not a format 1.0 archive, image out of range, region outside the image, patch
/// of another channel count, codec coded against its parent (ptm). Not thread-safe against
/// other writers of `path` (an advisory lock refuses a second concurrent writer).
[[nodiscard]] Result<UpdateReport> updateRegion(const std::string& path, uint32_t image, uint32_t x,
                                                uint32_t y, const Image& patch,
                                                const std::string& patch_name);

/// Appends the image of `options.inputs[0]` (tile size, border, codec and quality from
/// `options`; its output is ignored) as image `image_count`. The image is held in memory whole (at
/// most 32768 px a side); parent-coded codecs are refused.
[[nodiscard]] Result<UpdateReport> appendImage(const std::string& path, BuildOptions options);

/// What compaction wrote.
struct CompactReport {
  uint64_t bytes_before = 0;
  uint64_t bytes_after = 0;
};

/// Rewrites `path` into `output` (which may be `path` itself) without dead bytes: through a
/// temporary renamed into place, payloads in the clustering order the metadata records.
[[nodiscard]] Result<CompactReport> compactArchive(const std::string& path,
                                                   const std::string& output);

}  // namespace tessera::detail
