#include "build_budget.h"

#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <string_view>

#include <fmt/format.h>

#include <tessera/build.h>

#include "archive_writer.h"
#include "output/file_appender.h"
#include "output/output_file.h"

namespace tessera::detail {

namespace {

/// The program, its libraries and allocator slack: a build of a 64 x 64 image peaks at about
/// 20 MiB with 2 threads and 31 MiB with 16.
constexpr uint64_t kFixedBytes = uint64_t(48) << 20;
/// Per encoder thread beyond the above: its stack as touched, its malloc arena's slack.
constexpr uint64_t kPerThreadBytes = uint64_t(1) << 20;
/// The layout pass's write buffer (archive_writer.cpp).
constexpr uint64_t kLayoutBufferBytes = FileAppender::kBufferBytes;
/// A codec's per-thread state (zstd contexts, TurboJPEG handles, packing buffers) beyond the
/// tiles it works on.
constexpr uint64_t kCodecStateBytes = uint64_t(2) << 20;

/// Tiles of every level of an image.
uint64_t tileCount(const ImageInfo& info) {
  uint64_t tiles = 0;
  for (uint32_t l = 0; l < info.level_count; ++l)
    tiles += uint64_t(info.tilesX(l)) * info.tilesY(l);
  return tiles;
}

/// One image's rows: band, reader, one band per level, held tile rows.
uint64_t imageRowsBytes(const ImageInfo& info, const SourceInfo& source, Codec codec) {
  const uint64_t c = info.texelBytes();  // bytes per texel, whatever the sample type
  uint64_t bytes = uint64_t(bandRowsFor(info, source)) * info.width_px * c + source.buffer_bytes;
  const uint32_t band_rows = info.tile_size_px + 2 * info.border_px;
  for (uint32_t l = 0; l < info.level_count; ++l) {
    bytes += uint64_t(std::min(info.levelHeightPx(l), band_rows)) * info.levelWidthPx(l) * c;
    if (l + 1 < info.level_count) bytes += uint64_t(info.levelWidthPx(l + 1)) * c;
    // A codec coding against the parent level holds a tile row until its parent row exists
    // and that until both its children are queued: about three tile rows per level.
    if (codecNeedsParent(codec))
      bytes += uint64_t(std::min(info.tilesY(l), 3u)) * info.tilesX(l) * info.storedTileBytes();
  }
  return bytes;
}

/// The limit a cgroup file states, or 0 for none ("max", missing, unreadable).
uint64_t cgroupLimitBytes(const char* path) {
  std::ifstream in(path);
  std::string text;
  if (!(in >> text) || text == "max") return 0;
  uint64_t value = 0;
  for (char ch : text) {
    if (ch < '0' || ch > '9') return 0;
    value = value * 10 + uint64_t(ch - '0');
    if (value > (uint64_t(1) << 60)) return 0;  // v1 says "no limit" with a huge number
  }
  return value;
}

}  // namespace

uint32_t bandRowsFor(const ImageInfo& info, const SourceInfo& source) {
  const uint32_t natural = std::max(1u, source.natural_band_rows);
  const uint32_t rows =
      natural >= info.tile_size_px ? std::min(natural, 4 * info.tile_size_px) : info.tile_size_px;
  return std::min(rows, info.height_px);
}

MemoryEstimate estimateBuildMemory(std::span<const ImageInfo> infos,
                                   std::span<const SourceInfo* const> sources, Codec codec,
                                   uint32_t threads) {
  MemoryEstimate estimate;
  uint64_t max_tile_bytes = 0;
  for (size_t i = 0; i < infos.size(); ++i) {
    const uint64_t rows = imageRowsBytes(infos[i], *sources[i], codec);
    if (rows > estimate.rows_bytes) {
      estimate.rows_bytes = rows;
      estimate.costliest_image = i;
    }
    max_tile_bytes = std::max<uint64_t>(max_tile_bytes, infos[i].storedTileBytes());
    // The spool entry and the layout pass's entry copy for every tile, kept to the end; the
    // tile order and its sort keys for one image at a time (counted for all: an upper bound).
    estimate.directory_bytes +=
        tileCount(infos[i]) * (sizeof(SpoolEntry) + sizeof(TileEntry) + 2 * sizeof(TileId));
  }
  const uint64_t t = std::max(1u, threads);
  // 3T + 2 recycled tile buffers (an import's padded tiles); per encoder the tile it cuts, a
  // spool chunk (its capacity can double past the chunk size), the payload being appended, the
  // codec's scratch of a few tiles and its state.
  estimate.tiles_bytes = (3 * t + 2) * max_tile_bytes +
                         t * (2 * kSpoolChunkBytes + 11 * max_tile_bytes + kCodecStateBytes);
  estimate.fixed_bytes = kFixedBytes + t * kPerThreadBytes + kLayoutBufferBytes;
  return estimate;
}

Result<void> checkMemoryBudget(const MemoryEstimate& estimate, uint64_t limit_bytes,
                               const std::string& limit_origin, std::span<const ImageInfo> infos,
                               std::span<const std::string> inputs) {
  if (estimate.totalBytes() <= limit_bytes) return {};
  const ImageInfo& info = infos[estimate.costliest_image];
  const std::string others =
      infos.size() > 1 ? fmt::format(" with {} other image(s)", infos.size() - 1) : "";
  return fail(
      ErrorCode::kTooLarge,
      fmt::format("{}: claims {} x {} px with {} channel(s); building it{} with {} px tiles needs "
                  "about {} of memory (rows {}, tiles in flight {}, tile directory {}, program "
                  "{}), over the {} limit ({}); raise it with --memory-limit if the machine has "
                  "the memory, or check the file",
                  inputs[estimate.costliest_image], info.width_px, info.height_px, info.channels,
                  others, info.tile_size_px, formatByteCount(estimate.totalBytes()),
                  formatByteCount(estimate.rows_bytes), formatByteCount(estimate.tiles_bytes),
                  formatByteCount(estimate.directory_bytes), formatByteCount(estimate.fixed_bytes),
                  formatByteCount(limit_bytes), limit_origin));
}

uint64_t usableMemoryBytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES);
  const long page_bytes = ::sysconf(_SC_PAGE_SIZE);
  uint64_t bytes = pages > 0 && page_bytes > 0 ? uint64_t(pages) * uint64_t(page_bytes) : 0;
  for (const char* path :
       {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"}) {
    const uint64_t limit = cgroupLimitBytes(path);
    if (limit > 0 && (bytes == 0 || limit < bytes)) bytes = limit;
  }
  return bytes > 0 ? bytes : uint64_t(4) << 30;  // unknown: assume a small machine
}

uint64_t estimateArchiveBytes(std::span<const ImageInfo> infos, Codec codec, int quality) {
  // Archive bytes per pyramid byte near the low end of what docs/codecs.md measured: photos
  // and maps compress less, uniform and empty tiles (stored in the directory) more.
  double ratio = 0.25;
  switch (codec) {
    case Codec::kRaw: ratio = 1.0; break;
    case Codec::kLz4: ratio = 0.35; break;
    case Codec::kZstd:
    case Codec::kPng: ratio = 0.3; break;
    case Codec::kJpeg: ratio = 0.02 + 0.1 * std::max(0, quality - 85) / 15.0; break;
    default: break;
  }
  double bytes = 0;
  for (const ImageInfo& info : infos)
    bytes += double(info.width_px) * info.height_px * info.texelBytes() * 4 / 3;
  return uint64_t(bytes * ratio);
}

Result<void> checkFreeSpace(const std::string& output, const std::string& output_dir,
                            const std::string& spool_dir, uint64_t archive_bytes) {
  TESSERA_ASSIGN_OR_RETURN(DiskSpace at_output, diskSpaceAt(output_dir));
  TESSERA_ASSIGN_OR_RETURN(DiskSpace at_spool, diskSpaceAt(spool_dir));
  const bool shared = at_output.device == at_spool.device;
  auto refuse = [&](const std::string& dir, uint64_t needed, uint64_t available, const char* what) {
    return fail(ErrorCode::kIo,
                fmt::format("{}: {} need at least {} free in {} (a low estimate) but {} is "
                            "free; free some space{}",
                            output, what, formatByteCount(needed), dir, formatByteCount(available),
                            shared ? ", or put the spool elsewhere with --spool-dir" : ""));
  };
  if (shared) {
    if (at_output.available_bytes < 2 * archive_bytes)
      return refuse(output_dir, 2 * archive_bytes, at_output.available_bytes,
                    "the spool and the archive");
    return {};
  }
  if (at_spool.available_bytes < archive_bytes)
    return refuse(spool_dir, archive_bytes, at_spool.available_bytes, "the spool's tiles");
  if (at_output.available_bytes < archive_bytes)
    return refuse(output_dir, archive_bytes, at_output.available_bytes, "the archive's bytes");
  return {};
}

std::string formatByteCount(uint64_t bytes) {
  constexpr std::string_view kUnits[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  double value = double(bytes);
  size_t unit = 0;
  while (value >= 1024 && unit + 1 < std::size(kUnits)) {
    value /= 1024;
    ++unit;
  }
  return unit == 0 ? fmt::format("{} B", bytes) : fmt::format("{:.1f} {}", value, kUnits[unit]);
}

}  // namespace tessera::detail

namespace tessera {

uint64_t defaultBuildMemoryLimitBytes() {
  return detail::usableMemoryBytes() / 2;
}

}  // namespace tessera
