#pragma once
// The bounded cache of transcoded tiles (DZI, XYZ and ?format= responses): least recently used
// first out, bounded by the bytes of the cached bodies.

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>

namespace tessera::detail {

/// Thread-safe. A body larger than the whole budget is never stored. Two threads missing the
/// same key both compute it and the second insert replaces the first; that wastes one
/// encode but never blocks a thread on another's work.
class TranscodeCache {
 public:
  explicit TranscodeCache(uint64_t capacity_bytes) : capacity_bytes_(capacity_bytes) {}

  /// The cached body for `key`, or null; counts a hit or a miss.
  std::shared_ptr<const std::string> find(const std::string& key);
  /// Stores `body` under `key`, evicting least recently used entries to stay within budget.
  void insert(const std::string& key, std::shared_ptr<const std::string> body);

  struct Stats {
    uint64_t hits = 0;
    uint64_t misses = 0;
    uint64_t evictions = 0;
    uint64_t bytes = 0;  ///< bodies held now
    uint64_t entries = 0;
    uint64_t capacity_bytes = 0;
  };
  Stats stats() const;

 private:
  struct Entry {
    std::string key;
    std::shared_ptr<const std::string> body;
  };
  const uint64_t capacity_bytes_;
  mutable std::mutex mutex_;  // guards everything below
  std::list<Entry> lru_;      // front = most recently used
  std::unordered_map<std::string, std::list<Entry>::iterator> index_;
  uint64_t bytes_ = 0;
  uint64_t hits_ = 0, misses_ = 0, evictions_ = 0;
};

}  // namespace tessera::detail
