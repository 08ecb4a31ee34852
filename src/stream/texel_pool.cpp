#include "texel_pool.h"

namespace tessera::detail {

std::vector<uint8_t> TexelPool::take(size_t bytes) {
  std::lock_guard lock(mutex_);
  // Newest first: its pages are the likeliest still in the CPU caches.
  for (size_t i = idle_.size(); i-- > 0;) {
    if (idle_[i].size() != bytes) continue;
    std::vector<uint8_t> buffer = std::move(idle_[i]);
    idle_.erase(idle_.begin() + ptrdiff_t(i));
    idle_bytes_ -= bytes;
    return buffer;
  }
  return {};
}

void TexelPool::give(std::vector<uint8_t>&& buffer) {
  if (buffer.empty()) return;
  std::vector<uint8_t> freed;  // released outside the lock
  std::lock_guard lock(mutex_);
  if (idle_bytes_ + buffer.size() > max_bytes_) {
    freed = std::move(buffer);
    return;
  }
  idle_bytes_ += buffer.size();
  idle_.push_back(std::move(buffer));
}

std::shared_ptr<DecodedTile> TexelPool::makeTile(const TileId& id, Image&& texels) {
  auto* tile = new DecodedTile{id, std::move(texels)};
  return std::shared_ptr<DecodedTile>(tile, [pool = shared_from_this()](DecodedTile* done) {
    pool->give(std::move(done->texels.texels));
    delete done;
  });
}

uint64_t TexelPool::idleBytes() const {
  std::lock_guard lock(mutex_);
  return idle_bytes_;
}

}  // namespace tessera::detail
