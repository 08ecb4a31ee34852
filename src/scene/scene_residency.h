#pragma once
// Which texture levels to load and which to evict under a texel budget (issue 28, item 5;
// Marvie & Bouatouch, seed 003 part III). Policy only: no I/O, no threads, no texels, so tests
// drive it frame by frame. Owned by one thread (the streamer's render thread).

#include <cstdint>
#include <vector>

namespace tessera::detail {

/// A level whose texels the budget counts.
struct LevelRef {
  uint32_t texture = 0;
  uint32_t level = 0;
  friend bool operator==(const LevelRef&, const LevelRef&) = default;
};

/// What one visible texture needs this frame (the finest level any visible user needs, and
/// the screen pixels of those users).
struct TextureDemand {
  uint32_t texture = 0;
  uint32_t wanted_level = 0;
  uint64_t pixels = 0;
};

/// A texture's resident levels are a chain: `resident` and every coarser one. The coarsest is
/// pinned (never evicted, outside the budget), so a texture is never without texels.
class SceneResidency {
 public:
  /// level_bytes[t][L]: texel bytes of level L of texture t; the last entry is the coarsest.
  explicit SceneResidency(std::vector<std::vector<uint64_t>> level_bytes);

  /// Starts a frame: every texture not in `demands` wants its coarsest level.
  void setDemand(const std::vector<TextureDemand>& demands);

  /// Next levels to load, most missed screen first: for each visible texture whose resident
  /// level is coarser than wanted (and not `busy`), the next finer level, ranked by pixels x
  /// (resident - wanted) (ties: lower texture index). A level is left out when it cannot fit
  /// in `budget_bytes` even after evicting every level no visible texture needs.
  std::vector<LevelRef> nextLoads(uint64_t budget_bytes, const std::vector<bool>& busy) const;

  /// A loaded level: valid only for the next finer level of the chain (resident - 1); others
  /// (a stale result after an eviction) return false and change nothing.
  bool loaded(const LevelRef& level);

  /// Evicts finest levels until the budgeted bytes fit `budget_bytes`, returning them in the
  /// order dropped: first levels finer than their texture wants (textures out of view, oldest
  /// seen first, then larger levels first), then wanted levels of the textures covering the
  /// fewest pixels. Never the coarsest.
  std::vector<LevelRef> evictTo(uint64_t budget_bytes);

  uint32_t resident(uint32_t texture) const { return textures_[texture].resident; }
  uint32_t wanted(uint32_t texture) const { return textures_[texture].wanted; }
  uint32_t coarsest(uint32_t texture) const { return textures_[texture].coarsest; }
  uint64_t budgetedBytes() const { return budgeted_bytes_; }
  uint64_t pinnedBytes() const { return pinned_bytes_; }
  uint64_t levelBytes(uint32_t texture, uint32_t level) const {
    return level_bytes_[texture][level];
  }
  uint32_t textureCount() const { return uint32_t(textures_.size()); }

 private:
  struct TextureState {
    uint32_t coarsest = 0;
    uint32_t resident = 0;  ///< finest resident level; == coarsest when only it is
    uint32_t wanted = 0;
    uint64_t pixels = 0;
    uint64_t last_seen_frame = 0;  ///< the last frame it was in a demand
  };
  // Textures with a level finer than their coarsest resident: the eviction candidates.
  std::vector<uint32_t> refined_;
  std::vector<std::vector<uint64_t>> level_bytes_;
  std::vector<TextureState> textures_;
  std::vector<uint32_t> demanded_;  ///< the textures of the current frame's demands
  uint64_t budgeted_bytes_ = 0;
  uint64_t pinned_bytes_ = 0;
  uint64_t frame_ = 0;
};

}  // namespace tessera::detail
