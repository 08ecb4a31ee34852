// Viewer-shift eviction (Luo & Duan, section 3.4). LRU evicts the row the viewer just left
// behind last and the row ahead (cached but not yet shown) first; this policy does the
// opposite: tiles outside the expanded clip regions go first, ordered by their projection on
// the motion vector, the farthest behind the motion first.
#include <algorithm>
#include <cmath>
#include <unordered_set>

#include <tessera/cache.h>

namespace tessera {

namespace {

class ViewerShiftPolicy final : public EvictionPolicy {
 public:
  const char* name() const override { return "viewer-shift"; }
  void onInsert(const TileId& id) override { tiles_.insert(id); }
  void onAccess(const TileId&) override {}
  void onErase(const TileId& id) override { tiles_.erase(id); }
  void onViewerMotion(const ViewerMotion& motion) override {
    double length = std::hypot(motion.motion_x, motion.motion_y);
    // Keep the last direction while the viewer is still: where it came from is still behind.
    if (length > 0) {
      direction_x_ = motion.motion_x / length;
      direction_y_ = motion.motion_y / length;
    }
    centre_x_ = motion.centre_x;
    centre_y_ = motion.centre_y;
    keep_ = motion.keep_regions;
    tile_size_px_ = motion.tile_size_px;
  }

  void victims(size_t count, std::vector<TileId>& out) override {
    struct Candidate {
      bool kept;
      uint32_t level;
      double score;  ///< lower goes first
      TileId id;
    };
    std::vector<Candidate> candidates;
    candidates.reserve(tiles_.size());
    for (const TileId& id : tiles_) {
      // The tile's nearest point to the viewer, in level-0 pixels: a coarse tile's centre can
      // be far away while the tile lies right under the view.
      double span = std::ldexp(double(tile_size_px_), int(id.level));
      double x0 = id.x * span, y0 = id.y * span;
      double nx = std::clamp(centre_x_, x0, x0 + span), ny = std::clamp(centre_y_, y0, y0 + span);
      double dx = nx - centre_x_, dy = ny - centre_y_;
      bool kept = isKept(id);
      // Projection on the motion vector: most negative = farthest behind.
      double projection = dx * direction_x_ + dy * direction_y_;
      double distance = std::hypot(dx, dy);
      double score = (direction_x_ != 0 || direction_y_ != 0) ? projection : -distance;
      if (kept) score = -distance;  // among kept tiles, farthest from the viewer first
      candidates.push_back({kept, id.level, score, id});
    }
    size_t take = std::min(count, candidates.size());
    // Kept tiles go last and finest level first among them: a coarse tile is the parent the
    // finer ones need on screen, and covers the most for its bytes.
    std::partial_sort(candidates.begin(), candidates.begin() + take, candidates.end(),
                      [](const Candidate& a, const Candidate& b) {
                        if (a.kept != b.kept) return !a.kept;
                        if (a.kept && a.level != b.level) return a.level < b.level;
                        return a.score < b.score;
                      });
    for (size_t i = 0; i < take; ++i) out.push_back(candidates[i].id);
  }

 private:
  bool isKept(const TileId& id) const {
    for (const ViewerMotion::LevelRegion& r : keep_)
      if (r.image == id.image && r.level == id.level && int64_t(id.x) >= r.x0 &&
          int64_t(id.x) < r.x1 && int64_t(id.y) >= r.y0 && int64_t(id.y) < r.y1)
        return true;
    return false;
  }

  std::unordered_set<TileId, TileIdHash> tiles_;
  double direction_x_ = 0, direction_y_ = 0;
  double centre_x_ = 0, centre_y_ = 0;
  uint32_t tile_size_px_ = 256;
  std::vector<ViewerMotion::LevelRegion> keep_;
};

}  // namespace

std::unique_ptr<EvictionPolicy> makeViewerShiftPolicy() {
  return std::make_unique<ViewerShiftPolicy>();
}

}  // namespace tessera
