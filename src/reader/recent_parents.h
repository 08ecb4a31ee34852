#pragma once
// The archive's cache of decoded parents, for readers that hold no decoded tiles of their own
// (region reads, verify, extract, the server): the four children of a parent, read one after
// another, decode it once. The streamer's loader passes its decoded-tile cache instead.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <unordered_map>

#include "reader/parent_chain.h"

namespace tessera::detail {

/// Recently decoded parents, first in first out within a byte budget. Thread-safe.
class RecentParents final : public ParentStore {
 public:
  static constexpr size_t kDefaultBudgetBytes = 32u << 20;
  explicit RecentParents(size_t budget_bytes = kDefaultBudgetBytes) : budget_bytes_(budget_bytes) {}

  std::shared_ptr<const Image> find(const TileId& id) override;
  /// Keeps `texels`, dropping the oldest tiles while the budget is exceeded (the newest tile
  /// stays even when it alone exceeds it). A tile already kept is left as it is.
  void offer(const TileId& id, const std::shared_ptr<const Image>& texels) override;

  size_t bytes() const;

 private:
  const size_t budget_bytes_;
  mutable std::mutex mutex_;  // guards tiles_, order_ and bytes_
  std::unordered_map<uint64_t, std::shared_ptr<const Image>> tiles_;  ///< by tileKey
  std::deque<uint64_t> order_;  ///< keys of tiles_, oldest first
  size_t bytes_ = 0;            ///< texel bytes of tiles_
};

}  // namespace tessera::detail
