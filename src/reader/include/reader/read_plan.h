#pragma once
// How ByteSource::readMany groups ranges into reads: shared by the default implementation and
// sources that run the reads differently (the HTTP source sends them in parallel).

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <tessera/byte_source.h>

namespace tessera::detail {

/// One read covering one or more of the caller's ranges.
struct ReadRun {
  uint64_t offset_bytes = 0;
  uint64_t length_bytes = 0;
  std::vector<size_t> members;  ///< indices into the caller's ranges, in file order
};

/// Ranges closer than this are read as one by readMany: one request instead of two costs less
/// than the gap's bytes on every source we know (disk seek, HTTP round trip).
inline constexpr uint64_t kReadManyGapBytes = 64 * 1024;
/// The most bytes one merged read spans.
inline constexpr uint64_t kReadManyMaxBytes = 16u << 20;

/// Sorts `ranges` by offset and merges neighbours whose gap is at most `gap_bytes`, as long
/// as a run spans at most `max_bytes` (a single range longer than that is its own run).
std::vector<ReadRun> planReadRuns(std::span<const ByteRange> ranges,
                                  uint64_t gap_bytes = kReadManyGapBytes,
                                  uint64_t max_bytes = kReadManyMaxBytes);

/// Copies each member's bytes out of a run's buffer (read at run.offset_bytes).
void scatterRun(const ReadRun& run, std::span<const ByteRange> ranges,
                std::span<const uint8_t> bytes);

}  // namespace tessera::detail
