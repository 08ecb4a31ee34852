#pragma once
/// \file
/// Split builds: `tessera build --part I/N` builds one horizontal share of an image's base
/// level, and mergeArchiveParts joins the N parts into the archive a single build with the
/// same options writes, byte for byte (docs/builder.md, "Split and merge").

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <tessera/build.h>
#include <tessera/result.h>

namespace tessera {

/// Part I of N, I counted from 1 (Slurm's SLURM_ARRAY_TASK_ID with --array=1-N).
struct PartSpec {
  uint32_t index = 0;  ///< 1..count
  uint32_t count = 0;  ///< 1..kMaxBuildParts
};

/// Most parts a build may be split into.
inline constexpr uint32_t kMaxBuildParts = 65536;

/// Parses "I/N" (decimal, 1 <= I <= N <= kMaxBuildParts); kInvalidArgument naming the text and
/// what is accepted otherwise.
[[nodiscard]] Result<PartSpec> parsePartSpec(const std::string& text);

/// Builds part `part` of the single-input build `options` into `options.output`, a valid
/// archive that records the part, the build's options and the input's identity for the merge.
/// Refuses several inputs, row sources and the ptm codec (its tiles are coded against parents
/// that another part computes). Same failure guarantees as buildArchive.
[[nodiscard]] Result<BuildReport> buildArchivePart(
    const BuildOptions& options, PartSpec part,
    const std::function<void(const BuildProgress&)>& on_progress = {},
    const std::atomic<bool>* cancel = nullptr);

/// What a merge reports.
struct MergeReport {
  uint64_t output_bytes = 0;
  uint64_t payload_bytes_copied = 0;  ///< payloads copied from the parts, unchanged
  uint64_t tiles_copied = 0;
  /// Reads of the parts that fetched those payloads: one per stretch of the output stored
  /// together in a part, cut at 1 MiB, so far fewer than the tiles.
  uint64_t part_reads = 0;
  uint64_t tiles_computed = 0;  ///< tiles of the coarse levels, computed by the merge
  double elapsed_s = 0;
  /// Where elapsed_s went, in order: opening and checking the parts and gathering the
  /// output's directory from them; computing the coarse levels; writing payloads, directory
  /// and header; fsync and rename.
  double open_s = 0;
  double coarse_s = 0;
  double copy_s = 0;
  double commit_s = 0;
};

/// Writes `output` (atomically) from all N parts of one split build, given in any order.
/// Refuses, naming the file and the problem: a file that is not a part, parts of other
/// builds (options, input or N differ), duplicate and missing parts.
[[nodiscard]] Result<MergeReport> mergeArchiveParts(const std::vector<std::string>& parts,
                                                    const std::string& output,
                                                    const std::atomic<bool>* cancel = nullptr);

}  // namespace tessera
