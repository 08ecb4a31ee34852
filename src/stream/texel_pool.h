#pragma once
// Buffers of decoded tiles that left the cache, and fresh ones idle loaders fault in ahead of
// need (LoaderPool prewarming), kept for the next decodes. A tile decoded into a recycled
// buffer costs no allocation, no zeroing and no page faults, which for a fresh buffer can
// cost most of what the decode itself does (docs/runtime.md has the figures).
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include <tessera/cache.h>

namespace tessera::detail {

/// Thread-safe. Holds at most `max_bytes` of idle buffers; what does not fit is freed.
class TexelPool : public std::enable_shared_from_this<TexelPool> {
 public:
  explicit TexelPool(uint64_t max_bytes) : max_bytes_(max_bytes) {}

  /// A buffer of exactly `bytes` bytes with unspecified contents, or an empty vector when
  /// none is idle (the caller then allocates).
  std::vector<uint8_t> take(size_t bytes);
  /// Keeps `buffer` for a later take, or frees it when the pool is full.
  void give(std::vector<uint8_t>&& buffer);
  /// A cache tile whose texels come back here when the last reference goes (eviction, or the
  /// renderer dropping an uploaded tile). The pool lives as long as such tiles do.
  std::shared_ptr<DecodedTile> makeTile(const TileId& id, Image&& texels);

  uint64_t idleBytes() const;

 private:
  const uint64_t max_bytes_;
  mutable std::mutex mutex_;
  std::vector<std::vector<uint8_t>> idle_;
  uint64_t idle_bytes_ = 0;
};

}  // namespace tessera::detail
