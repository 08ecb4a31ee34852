// The ByteSource interface lives with the archive reader that consumes it; the file and
// memory implementations are in the stream module.
#include <tessera/byte_source.h>

#include <algorithm>
#include <cstring>
#include <numeric>
#include <string>

namespace tessera {

Result<void> ByteSource::readMany(std::span<const ByteRange> ranges) const {
  // Ranges closer than this are read as one: one request instead of two costs less than
  // the gap's bytes on every source we know (disk seek, HTTP round trip).
  constexpr uint64_t kMergeGapBytes = 64 * 1024;
  constexpr uint64_t kMaxMergedBytes = 16u << 20;
  std::vector<size_t> order(ranges.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return ranges[a].offset_bytes < ranges[b].offset_bytes; });
  std::vector<uint8_t> merged;
  for (size_t i = 0; i < order.size();) {
    const ByteRange& first = ranges[order[i]];
    uint64_t begin = first.offset_bytes, end = first.offset_bytes + first.length_bytes;
    size_t j = i + 1;
    while (j < order.size()) {
      const ByteRange& next = ranges[order[j]];
      uint64_t next_end = std::max(end, next.offset_bytes + next.length_bytes);
      if (next.offset_bytes > end + kMergeGapBytes || next_end - begin > kMaxMergedBytes) break;
      end = next_end;
      ++j;
    }
    if (j == i + 1) {
      TESSERA_TRY(read(first.offset_bytes, {first.out, size_t(first.length_bytes)}));
    } else {
      merged.resize(end - begin);
      TESSERA_TRY(read(begin, merged));
      for (size_t k = i; k < j; ++k) {
        const ByteRange& range = ranges[order[k]];
        if (range.length_bytes)
          std::memcpy(range.out, merged.data() + (range.offset_bytes - begin), range.length_bytes);
      }
    }
    i = j;
  }
  return {};
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
