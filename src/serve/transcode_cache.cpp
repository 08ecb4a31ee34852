#include "transcode_cache.h"

namespace tessera::detail {

std::shared_ptr<const std::string> TranscodeCache::find(const std::string& key) {
  std::lock_guard lock(mutex_);
  auto it = index_.find(key);
  if (it == index_.end()) {
    ++misses_;
    return nullptr;
  }
  ++hits_;
  lru_.splice(lru_.begin(), lru_, it->second);
  return it->second->body;
}

void TranscodeCache::insert(const std::string& key, std::shared_ptr<const std::string> body) {
  if (!body || body->size() > capacity_bytes_) return;
  std::lock_guard lock(mutex_);
  auto it = index_.find(key);
  if (it != index_.end()) {
    bytes_ -= it->second->body->size();
    lru_.erase(it->second);
    index_.erase(it);
  }
  while (!lru_.empty() && bytes_ + body->size() > capacity_bytes_) {
    bytes_ -= lru_.back().body->size();
    index_.erase(lru_.back().key);
    lru_.pop_back();
    ++evictions_;
  }
  bytes_ += body->size();
  lru_.push_front({key, std::move(body)});
  index_[key] = lru_.begin();
}

TranscodeCache::Stats TranscodeCache::stats() const {
  std::lock_guard lock(mutex_);
  return {hits_, misses_, evictions_, bytes_, uint64_t(lru_.size()), capacity_bytes_};
}

}  // namespace tessera::detail
