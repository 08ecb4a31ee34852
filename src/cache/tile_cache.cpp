#include <tessera/cache.h>

#include <algorithm>

#include <tessera/check.h>

namespace tessera {

TileCache::TileCache(size_t budget_bytes, std::unique_ptr<EvictionPolicy> policy)
    : budget_bytes_(budget_bytes), policy_(std::move(policy)) {}

TileCache::~TileCache() = default;

std::shared_ptr<const DecodedTile> TileCache::find(const TileId& id) {
  std::lock_guard lock(mutex_);
  auto it = slots_.find(id);
  if (it == slots_.end()) {
    ++stats_.misses;
    return nullptr;
  }
  ++stats_.hits;
  policy_->onAccess(id);
  return it->second.tile;
}

bool TileCache::contains(const TileId& id) const {
  std::lock_guard lock(mutex_);
  return slots_.count(id) > 0;
}

bool TileCache::makeRoomLocked(size_t bytes) {
  if (bytes > budget_bytes_) return false;
  while (stats_.bytes + stats_.reserved_bytes + bytes > budget_bytes_) {
    size_t over = stats_.bytes + stats_.reserved_bytes + bytes - budget_bytes_;
    // Ask for a few more candidates than the bytes strictly need: some may be pinned.
    size_t average = stats_.tiles ? std::max<size_t>(1, stats_.bytes / stats_.tiles) : 1;
    size_t want = over / average + 1 + stats_.pinned;
    scratch_victims_.clear();
    policy_->victims(std::min(want, slots_.size()), scratch_victims_);
    bool evicted_any = false;
    for (const TileId& victim : scratch_victims_) {
      auto it = slots_.find(victim);
      if (it == slots_.end() || it->second.pins > 0) continue;
      stats_.bytes -= it->second.tile->bytes();
      --stats_.tiles;
      ++stats_.evictions;
      policy_->onErase(victim);
      slots_.erase(it);
      evicted_any = true;
      if (stats_.bytes + stats_.reserved_bytes + bytes <= budget_bytes_) break;
    }
    if (!evicted_any) return false;
  }
  return true;
}

bool TileCache::insert(std::shared_ptr<const DecodedTile> tile) {
  std::lock_guard lock(mutex_);
  const TileId id = tile->id;
  uint32_t pins = 0;
  if (auto it = slots_.find(id); it != slots_.end()) {
    pins = it->second.pins;
    stats_.bytes -= it->second.tile->bytes();
    --stats_.tiles;
    if (pins) --stats_.pinned;
    policy_->onErase(id);
    slots_.erase(it);
  }
  if (auto early = early_pins_.find(id); early != early_pins_.end()) {
    pins += early->second;
    early_pins_.erase(early);
  }
  size_t bytes = tile->bytes();
  if (!makeRoomLocked(bytes)) {
    ++stats_.rejected;
    if (pins) early_pins_[id] = pins;
    return false;
  }
  slots_[id] = {std::move(tile), pins};
  stats_.bytes += bytes;
  ++stats_.tiles;
  ++stats_.insertions;
  if (pins) ++stats_.pinned;
  stats_.peak_bytes = std::max(stats_.peak_bytes, stats_.bytes + stats_.reserved_bytes);
  policy_->onInsert(id);
  return true;
}

void TileCache::findAndPin(std::span<const TileId> ids,
                           std::vector<std::shared_ptr<const DecodedTile>>& out) {
  std::lock_guard lock(mutex_);
  for (const TileId& id : ids) {
    auto it = slots_.find(id);
    if (it == slots_.end()) {
      ++stats_.misses;
      out.push_back(nullptr);
      continue;
    }
    ++stats_.hits;
    policy_->onAccess(id);
    if (it->second.pins++ == 0) ++stats_.pinned;
    out.push_back(it->second.tile);
  }
}

std::shared_ptr<const DecodedTile> TileCache::pinIfCached(const TileId& id) {
  std::lock_guard lock(mutex_);
  auto it = slots_.find(id);
  if (it == slots_.end()) return nullptr;
  policy_->onAccess(id);
  if (it->second.pins++ == 0) ++stats_.pinned;
  return it->second.tile;
}

void TileCache::pin(const TileId& id) {
  std::lock_guard lock(mutex_);
  auto it = slots_.find(id);
  if (it == slots_.end()) {
    ++early_pins_[id];
    return;
  }
  if (it->second.pins++ == 0) ++stats_.pinned;
}

void TileCache::unpin(const TileId& id) {
  std::lock_guard lock(mutex_);
  auto it = slots_.find(id);
  if (it == slots_.end()) {
    auto early = early_pins_.find(id);
    if (early != early_pins_.end() && --early->second == 0) early_pins_.erase(early);
    return;
  }
  TESSERA_CHECK(it->second.pins > 0) << "unpin of a tile that is not pinned";
  if (--it->second.pins == 0) --stats_.pinned;
}

bool TileCache::reserve(size_t bytes) {
  std::lock_guard lock(mutex_);
  if (!makeRoomLocked(bytes)) return false;
  stats_.reserved_bytes += bytes;
  stats_.peak_bytes = std::max(stats_.peak_bytes, stats_.bytes + stats_.reserved_bytes);
  return true;
}

void TileCache::unreserve(size_t bytes) {
  std::lock_guard lock(mutex_);
  TESSERA_CHECK(stats_.reserved_bytes >= bytes) << "unreserve of more than reserved";
  stats_.reserved_bytes -= bytes;
}

void TileCache::erase(const TileId& id) {
  std::lock_guard lock(mutex_);
  auto it = slots_.find(id);
  if (it == slots_.end()) return;
  stats_.bytes -= it->second.tile->bytes();
  --stats_.tiles;
  if (it->second.pins) --stats_.pinned;
  policy_->onErase(id);
  slots_.erase(it);
}

void TileCache::setViewerMotion(const ViewerMotion& motion) {
  std::lock_guard lock(mutex_);
  policy_->onViewerMotion(motion);
}

CacheStats TileCache::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

const char* TileCache::policyName() const {
  return policy_->name();
}

}  // namespace tessera
