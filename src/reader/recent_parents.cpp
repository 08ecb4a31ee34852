#include "recent_parents.h"

namespace tessera::detail {
namespace {

// Images < 2^16, levels < 2^5 and tile columns and rows < 2^18 (kMaxImageSidePx over the
// smallest tile) pack into 57 bits.
uint64_t tileKey(const TileId& tile) {
  return (uint64_t(tile.image) << 41) | (uint64_t(tile.level) << 36) | (uint64_t(tile.x) << 18) |
         tile.y;
}

}  // namespace

std::shared_ptr<const Image> RecentParents::find(const TileId& id) {
  std::lock_guard lock(mutex_);
  auto it = tiles_.find(tileKey(id));
  return it == tiles_.end() ? nullptr : it->second;
}

void RecentParents::offer(const TileId& id, const std::shared_ptr<const Image>& texels) {
  std::lock_guard lock(mutex_);
  const uint64_t key = tileKey(id);
  if (!tiles_.emplace(key, texels).second) return;
  bytes_ += texels->texels.size();
  order_.push_back(key);
  while (bytes_ > budget_bytes_ && order_.size() > 1) {
    auto oldest = tiles_.find(order_.front());
    bytes_ -= oldest->second->texels.size();
    tiles_.erase(oldest);
    order_.pop_front();
  }
}

size_t RecentParents::bytes() const {
  std::lock_guard lock(mutex_);
  return bytes_;
}

}  // namespace tessera::detail
