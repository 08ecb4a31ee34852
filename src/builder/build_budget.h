#pragma once
// What a build needs before it starts, from the sizes its inputs claim: memory against the
// limit (BuildOptions::memory_limit_bytes) and free space where the spool and the archive go.
// Both are checked after the sources' headers are read and before any band, pyramid or tile
// buffer exists, so a 57-byte PNG claiming 16777216 x 16777216 px is refused with a message
// naming it rather than failing an allocation (docs/builder.md, "Memory budget").

#include <cstdint>
#include <span>
#include <string>

#include <tessera/format.h>
#include <tessera/result.h>

#include "band_reader.h"

namespace tessera::detail {

/// Each encoder batches payloads into a chunk of about this size and writes it to the spool in
/// one call.
inline constexpr size_t kSpoolChunkBytes = size_t(4) << 20;

/// Rows the builder reads per call for an image: the reader's natural band when that is at
/// least a tile (up to four tiles), else one tile's rows; never more than the image has.
uint32_t bandRowsFor(const ImageInfo& info, const SourceInfo& source);

/// The parts of a build's memory, in bytes: upper bounds, each the sum of the buffers
/// docs/builder.md lists under "Memory budget".
struct MemoryEstimate {
  /// The costliest image's rows: its input band, its reader's buffers, one band per level
  /// and, for a codec that codes against the parent level, the tile rows held for it.
  uint64_t rows_bytes = 0;
  /// Tiles in flight: per encoder the tile it cuts, its spool chunk (which can grow to twice
  /// kSpoolChunkBytes) and codec scratch, and an import's padded tiles.
  uint64_t tiles_bytes = 0;
  /// One entry per tile of every image, kept until the layout pass, and that pass's copies
  /// and tile order.
  uint64_t directory_bytes = 0;
  /// The program, its libraries, allocator slack and the layout pass's write buffer.
  uint64_t fixed_bytes = 0;
  size_t costliest_image = 0;  ///< the image rows_bytes belongs to

  uint64_t totalBytes() const { return rows_bytes + tiles_bytes + directory_bytes + fixed_bytes; }
};

/// The memory a build of `infos` (level_count set) needs; `sources[i]` is what the reader of
/// image i reported and `threads` (at least 1) the encoder threads. Pure arithmetic in 64 bits:
/// no overflow for sides up to kMaxImageSidePx and threads up to kMaxBuildThreads.
MemoryEstimate estimateBuildMemory(std::span<const ImageInfo> infos,
                                   std::span<const SourceInfo* const> sources, Codec codec,
                                   uint32_t threads);

/// Fails with kTooLarge when `estimate` is over `limit_bytes`, naming the costliest input (from
/// `inputs`), the size it claims and the memory the build needs; `limit_origin` says where the
/// limit came from ("--memory-limit", "half of physical memory").
[[nodiscard]] Result<void> checkMemoryBudget(const MemoryEstimate& estimate, uint64_t limit_bytes,
                                             const std::string& limit_origin,
                                             std::span<const ImageInfo> infos,
                                             std::span<const std::string> inputs);

/// Memory the machine lends this process: physical memory (sysconf), or the control group's
/// limit where lower (cgroup v2 memory.max, v1 memory.limit_in_bytes).
uint64_t usableMemoryBytes();

/// A deliberately low estimate of the archive's size (and so of the spool's): the pyramid's
/// pixels times a compression ratio near the best real images reach for `codec` (JPEG by
/// quality). Refusing a build below it refuses only builds that cannot fit.
uint64_t estimateArchiveBytes(std::span<const ImageInfo> infos, Codec codec, int quality);

/// Fails with kIo when the free space cannot hold the spool (in `spool_dir`) and the archive
/// (in `output_dir`), both about `archive_bytes`: twice that when they share a file system.
/// The message names the directory, the space needed and the space free.
[[nodiscard]] Result<void> checkFreeSpace(const std::string& output, const std::string& output_dir,
                                          const std::string& spool_dir, uint64_t archive_bytes);

/// "12.3 GiB".
std::string formatByteCount(uint64_t bytes);

}  // namespace tessera::detail
