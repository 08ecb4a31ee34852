// The ByteSource interface's shared behaviour: batched reads merged by planReadRuns.
#include <tessera/byte_source.h>

#include <algorithm>
#include <cstring>
#include <numeric>
#include <string>

#include "reader/read_plan.h"

namespace tessera {

namespace detail {

std::vector<ReadRun> planReadRuns(std::span<const ByteRange> ranges, uint64_t gap_bytes,
                                  uint64_t max_bytes) {
  std::vector<size_t> order(ranges.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return ranges[a].offset_bytes < ranges[b].offset_bytes; });
  std::vector<ReadRun> runs;
  for (size_t i : order) {
    const ByteRange& range = ranges[i];
    const uint64_t range_end = range.offset_bytes + range.length_bytes;
    if (!runs.empty()) {
      ReadRun& last = runs.back();
      const uint64_t end = last.offset_bytes + last.length_bytes;
      const uint64_t merged_end = std::max(end, range_end);
      if (range.offset_bytes <= end + gap_bytes && merged_end - last.offset_bytes <= max_bytes) {
        last.length_bytes = merged_end - last.offset_bytes;
        last.members.push_back(i);
        continue;
      }
    }
    runs.push_back({range.offset_bytes, range.length_bytes, {i}});
  }
  return runs;
}

void scatterRun(const ReadRun& run, std::span<const ByteRange> ranges,
                std::span<const uint8_t> bytes) {
  for (size_t i : run.members) {
    const ByteRange& range = ranges[i];
    if (range.length_bytes)
      std::memcpy(range.out, bytes.data() + (range.offset_bytes - run.offset_bytes),
                  range.length_bytes);
  }
}

}  // namespace detail

Result<void> ByteSource::readMany(std::span<const ByteRange> ranges) const {
  std::vector<uint8_t> merged;
  for (const detail::ReadRun& run : detail::planReadRuns(ranges)) {
    if (run.members.size() == 1) {
      const ByteRange& range = ranges[run.members[0]];
      TESSERA_TRY(read(range.offset_bytes, {range.out, size_t(range.length_bytes)}));
    } else {
      merged.resize(run.length_bytes);
      TESSERA_TRY(read(run.offset_bytes, merged));
      detail::scatterRun(run, ranges, merged);
    }
  }
  return {};
}

std::vector<Result<void>> ByteSource::readEach(std::span<const ByteRange> ranges,
                                               const std::atomic<bool>& cancel) const {
  std::vector<Result<void>> results;
  results.reserve(ranges.size());
  for (const ByteRange& range : ranges)
    results.push_back(
        readCancellable(range.offset_bytes, {range.out, size_t(range.length_bytes)}, cancel));
  return results;
}

uint64_t ByteSource::prefetch(std::span<const ByteRange>) const {
  return 0;
}

Result<void> ByteSource::readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                                         const std::atomic<bool>& cancel) const {
  if (cancel.load(std::memory_order_acquire))
    return Unexpected(ErrorCode::kCancelled,
                      name() + ": read at offset " + std::to_string(offset_bytes) + " cancelled");
  return read(offset_bytes, out);
}

}  // namespace tessera
