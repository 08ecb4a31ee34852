#pragma once
/// \file
/// The decoded-tile cache: tiles in host memory under a byte budget that also counts buffers
/// in flight, with pinning and pluggable eviction (LRU, or the viewer-shift policy of
/// Luo & Duan, section 3.4). Policy is apart from mechanism: the cache asks an
/// `EvictionPolicy` for victims and never touches the GPU.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <unordered_map>
#include <vector>

#include <tessera/format.h>

namespace tessera {

/// Hash for TileId keys.
struct TileIdHash {
  size_t operator()(const TileId& id) const {
    uint64_t key = (uint64_t(id.image) << 48) ^ (uint64_t(id.level) << 42) ^
                   (uint64_t(id.x) << 21) ^ uint64_t(id.y);
    return size_t(key * 0x9E3779B97F4A7C15ull >> 7);
  }
};

/// A bc1 or bc7 tile kept as stored, for a renderer that uploads it to the GPU as it is
/// (docs/codecs.md, "bc1 (8) and bc7 (9)"): the stored tile's 4x4 blocks, row-major, the
/// tile padded to a multiple of 4 on each side.
struct StoredBlocks {
  Codec codec = Codec::kRaw;    ///< kBc1 or kBc7; kRaw: the tile is not kept as blocks
  uint32_t padded_side_px = 0;  ///< the stored side rounded up to a multiple of 4
  std::vector<uint8_t> bytes;   ///< (padded_side_px / 4)^2 blocks of 8 (bc1) or 16 (bc7) bytes
};

/// A loaded tile, immutable once cached: the stored tile with its borders, decoded (`texels`)
/// or, for a streamer that keeps bc1/bc7 payloads as stored, as blocks (`blocks`, with
/// `texels` empty).
struct DecodedTile {
  TileId id;
  Image texels;
  StoredBlocks blocks;
  /// True when the tile holds blocks instead of texels.
  bool keptAsBlocks() const { return blocks.codec != Codec::kRaw; }
  /// The bytes a renderer uploads: the blocks or the texels.
  std::span<const uint8_t> uploadBytes() const {
    return keptAsBlocks() ? std::span<const uint8_t>(blocks.bytes)
                          : std::span<const uint8_t>(texels.texels);
  }
  size_t bytes() const { return texels.texels.size() + blocks.bytes.size() + sizeof(DecodedTile); }
};

/// Counters since construction. `peak_bytes` includes reservations.
struct CacheStats {
  uint64_t hits = 0;
  uint64_t misses = 0;
  uint64_t insertions = 0;
  uint64_t evictions = 0;
  uint64_t rejected = 0;      ///< inserts refused because pinned tiles fill the budget
  size_t bytes = 0;           ///< cached tiles now
  size_t reserved_bytes = 0;  ///< buffers in flight now
  size_t peak_bytes = 0;      ///< max of bytes + reserved_bytes
  size_t tiles = 0;
  size_t pinned = 0;
};

/// Where the viewer is, for policies that evict by position. Level-0 pixel units.
struct ViewerMotion {
  double centre_x = 0;
  double centre_y = 0;
  double motion_x = 0;  ///< clip-centre offset since the previous frame (any length)
  double motion_y = 0;
  uint32_t tile_size_px = 256;  ///< converts tile addresses to level-0 pixels
  /// Tiles inside these regions (per level: [x0, x1) x [y0, y1) in tiles, already expanded)
  /// are kept if at all possible.
  struct LevelRegion {
    uint32_t image = 0;
    uint32_t level = 0;
    int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  };
  std::vector<LevelRegion> keep_regions;
};

/// Orders eviction candidates. Called by TileCache under its lock: implementations need no
/// locking of their own and must not call back into the cache. Owned by one cache.
class EvictionPolicy {
 public:
  virtual ~EvictionPolicy() = default;
  virtual const char* name() const = 0;
  virtual void onInsert(const TileId& id) = 0;
  virtual void onAccess(const TileId& id) = 0;
  virtual void onErase(const TileId& id) = 0;
  virtual void onViewerMotion(const ViewerMotion& motion) { (void)motion; }
  /// Appends candidates in the order they should go, at least `count` if that many tiles
  /// are known (the cache skips pinned ones and asks again if it needs more).
  virtual void victims(size_t count, std::vector<TileId>& out) = 0;
};

/// Least recently used (inserts and finds count as uses).
std::unique_ptr<EvictionPolicy> makeLruPolicy();
/// Luo & Duan, section 3.4: tiles outside the expanded clip regions go first, ordered by
/// their projection on the motion vector, farthest behind the motion first; then the rest by
/// distance from the viewer, farthest first.
std::unique_ptr<EvictionPolicy> makeViewerShiftPolicy();

/// Thread-safe. Lock order: the cache's mutex is a leaf (nothing else is locked under it).
class TileCache {
 public:
  TileCache(size_t budget_bytes, std::unique_ptr<EvictionPolicy> policy);
  ~TileCache();
  TileCache(const TileCache&) = delete;
  TileCache& operator=(const TileCache&) = delete;

  /// The tile, or null (a miss). Counts a hit or a miss and tells the policy.
  std::shared_ptr<const DecodedTile> find(const TileId& id);
  /// Like find without counting or touching the policy.
  bool contains(const TileId& id) const;
  /// Inserts (replacing a tile with the same id), evicting unpinned tiles as the policy
  /// orders until it fits. Returns false (and counts `rejected`) if pinned tiles leave no room.
  bool insert(std::shared_ptr<const DecodedTile> tile);
  /// For each id, the tile if cached (pinned, so it stays until `unpin`) or null; one lock for
  /// the whole batch, so a render thread pays one short critical section per frame.
  void findAndPin(std::span<const TileId> ids,
                  std::vector<std::shared_ptr<const DecodedTile>>& out);
  /// The tile pinned (the caller unpins it), or null without pinning when it is not cached.
  /// Counts neither a hit nor a miss; tells the policy of the use. The loader holds a parent
  /// tile this way while it decodes a child coded against it (a dependent codec, ptm), so the
  /// parent cannot be evicted half-way.
  std::shared_ptr<const DecodedTile> pinIfCached(const TileId& id);
  /// Pinned tiles are never evicted (the coarsest level, tiles being uploaded). Pins count.
  void pin(const TileId& id);
  void unpin(const TileId& id);
  /// Reserves budget for a buffer in flight (a read or decode under way), evicting if needed.
  /// Returns false when it cannot fit; the caller retries later.
  bool reserve(size_t bytes);
  void unreserve(size_t bytes);
  /// Removes a tile regardless of policy (e.g. the archive changed).
  void erase(const TileId& id);
  void setViewerMotion(const ViewerMotion& motion);
  CacheStats stats() const;
  size_t budgetBytes() const { return budget_bytes_; }
  const char* policyName() const;

 private:
  bool makeRoomLocked(size_t bytes);

  struct Slot {
    std::shared_ptr<const DecodedTile> tile;
    uint32_t pins = 0;
  };
  const size_t budget_bytes_;
  mutable std::mutex mutex_;  // guards everything below
  std::unique_ptr<EvictionPolicy> policy_;
  std::unordered_map<TileId, Slot, TileIdHash> slots_;
  std::unordered_map<TileId, uint32_t, TileIdHash> early_pins_;  ///< pins before insert
  CacheStats stats_;
  std::vector<TileId> scratch_victims_;
};

}  // namespace tessera
