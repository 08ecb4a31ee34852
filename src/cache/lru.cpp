// Least-recently-used eviction: a list in use order with an index into it.
#include <list>
#include <unordered_map>

#include <tessera/cache.h>

namespace tessera {

namespace {

class LruPolicy final : public EvictionPolicy {
 public:
  const char* name() const override { return "lru"; }
  void onInsert(const TileId& id) override { touch(id); }
  void onAccess(const TileId& id) override { touch(id); }
  void onErase(const TileId& id) override {
    auto it = index_.find(id);
    if (it == index_.end()) return;
    order_.erase(it->second);
    index_.erase(it);
  }
  void victims(size_t count, std::vector<TileId>& out) override {
    // Oldest first: the back of the list.
    for (auto it = order_.rbegin(); it != order_.rend() && count > 0; ++it, --count)
      out.push_back(*it);
  }

 private:
  void touch(const TileId& id) {
    auto it = index_.find(id);
    if (it != index_.end()) {
      order_.splice(order_.begin(), order_, it->second);
      return;
    }
    order_.push_front(id);
    index_[id] = order_.begin();
  }
  std::list<TileId> order_;  ///< most recent at the front
  std::unordered_map<TileId, std::list<TileId>::iterator, TileIdHash> index_;
};

}  // namespace

std::unique_ptr<EvictionPolicy> makeLruPolicy() {
  return std::make_unique<LruPolicy>();
}

}  // namespace tessera
