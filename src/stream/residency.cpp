#include "residency.h"

#include <algorithm>
#include <cmath>

namespace tessera::detail {

namespace {

constexpr double kClassStride = 1e12;
constexpr double kLevelStride = 1e8;

double levelScale(uint32_t level) {
  return std::ldexp(1.0, int(level));
}

/// Rays that miss the ground (above the horizon) are cut where one pixel covers a whole
/// coarsest-level tile: nothing finer could be seen there.
double farDistance(const PerspectiveView& v, const ImageInfo& info) {
  double coarsest_texel = levelScale(info.level_count - 1);
  return coarsest_texel * info.tile_size_px / pixelAngle(v);
}

}  // namespace

Footprint footprintOf(const View& view, const ImageInfo& info) {
  Footprint f;
  if (view.kind == View::Kind::kOrtho) {
    const OrthoView& o = view.ortho;
    double tpp = texelsPerPixelOf(o);
    double hw = o.viewport_w * 0.5 * tpp, hh = o.viewport_h * 0.5 * tpp;
    double c = std::abs(std::cos(o.rotation_rad)), s = std::abs(std::sin(o.rotation_rad));
    double ex = c * hw + s * hh, ey = s * hw + c * hh;
    f = {o.centre_x - ex,
         o.centre_y - ey,
         o.centre_x + ex,
         o.centre_y + ey,
         o.centre_x,
         o.centre_y,
         desiredLevelFor(tpp, info.level_count)};
    return f;
  }
  const PerspectiveView& p = view.perspective;
  double far = farDistance(p, info);
  double eye_z = std::max(p.eye_z, 1e-6);
  f.x0 = f.x1 = p.eye_x;
  f.y0 = f.y1 = p.eye_y;
  auto include = [&](double x, double y) {
    f.x0 = std::min(f.x0, x);
    f.x1 = std::max(f.x1, x);
    f.y0 = std::min(f.y0, y);
    f.y1 = std::max(f.y1, y);
  };
  // Sample the screen's edges, not just its corners: the ground trace of an edge bends once
  // it crosses the horizon.
  constexpr int kSteps = 8;
  for (int i = 0; i <= kSteps; ++i) {
    for (int j = 0; j <= kSteps; ++j) {
      if (i != 0 && i != kSteps && j != 0 && j != kSteps) continue;
      const Vec3 d = rayDirection(p, -1 + 2.0 * i / kSteps, -1 + 2.0 * j / kSteps);
      const double dx = d.x, dy = d.y, dz = d.z;
      double len = std::sqrt(dx * dx + dy * dy + dz * dz);
      double dist = dz < 0 ? std::min(far, eye_z / -dz * len) : far;
      include(p.eye_x + dx / len * dist, p.eye_y + dy / len * dist);
    }
  }
  f.centre_x = p.eye_x;
  f.centre_y = p.eye_y;
  // The nearest ground point inside the footprint is straight below the eye when that is
  // visible, else on the box: density there sets the finest level needed.
  double nx = std::clamp(p.eye_x, f.x0, f.x1), ny = std::clamp(p.eye_y, f.y0, f.y1);
  double d =
      std::sqrt((nx - p.eye_x) * (nx - p.eye_x) + (ny - p.eye_y) * (ny - p.eye_y) + eye_z * eye_z);
  f.desired_level = desiredLevelFor(d * pixelAngle(p), info.level_count);
  return f;
}

uint32_t requiredLevelForTile(const View& view, const ImageInfo& info, const TileId& tile,
                              uint32_t desired_level) {
  if (view.kind == View::Kind::kOrtho) return desired_level;
  const PerspectiveView& p = view.perspective;
  double span = levelScale(tile.level) * info.tile_size_px;
  double x0 = tile.x * span, y0 = tile.y * span;
  double nx = std::clamp(p.eye_x, x0, x0 + span), ny = std::clamp(p.eye_y, y0, y0 + span);
  double eye_z = std::max(p.eye_z, 1e-6);
  double d =
      std::sqrt((nx - p.eye_x) * (nx - p.eye_x) + (ny - p.eye_y) * (ny - p.eye_y) + eye_z * eye_z);
  return desiredLevelFor(d * pixelAngle(p), info.level_count);
}

ResidencyManager::ResidencyManager(const ImageInfo& info, uint32_t image,
                                   const ResidencyOptions& options)
    : info_(info), image_(image), options_(options), centres_(info.level_count) {}

TileRect ResidencyManager::gridRect(uint32_t level) const {
  return {0, 0, info_.tilesX(level), info_.tilesY(level)};
}

namespace {

TileRect intersect(const TileRect& a, const TileRect& b) {
  return {std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1), std::min(a.y1, b.y1)};
}

/// True when planning for `a` and `b` gives the same result: the same image, kind and, of
/// the kind's camera, every field.
bool sameView(const View& a, const View& b) {
  if (a.kind != b.kind || a.image != b.image) return false;
  if (a.kind == View::Kind::kOrtho) {
    const OrthoView &p = a.ortho, &q = b.ortho;
    return p.centre_x == q.centre_x && p.centre_y == q.centre_y &&
           p.texels_per_pixel == q.texels_per_pixel && p.viewport_w == q.viewport_w &&
           p.viewport_h == q.viewport_h && p.rotation_rad == q.rotation_rad;
  }
  const PerspectiveView &p = a.perspective, &q = b.perspective;
  return p.eye_x == q.eye_x && p.eye_y == q.eye_y && p.eye_z == q.eye_z && p.yaw_rad == q.yaw_rad &&
         p.pitch_rad == q.pitch_rad && p.fov_y_rad == q.fov_y_rad && p.viewport_w == q.viewport_w &&
         p.viewport_h == q.viewport_h && p.roll_rad == q.roll_rad;
}

/// Tiles of `level` under a box in level-0 pixels.
TileRect tilesUnder(double x0, double y0, double x1, double y1, uint32_t level, uint32_t t) {
  double span = levelScale(level) * t;
  return {int64_t(std::floor(x0 / span)), int64_t(std::floor(y0 / span)),
          int64_t(std::floor(x1 / span)) + 1, int64_t(std::floor(y1 / span)) + 1};
}

/// The same block of the image one or more levels coarser.
TileRect coarsen(const TileRect& r, uint32_t steps) {
  if (r.empty()) return r;
  return {r.x0 >> steps, r.y0 >> steps, ((r.x1 - 1) >> steps) + 1, ((r.y1 - 1) >> steps) + 1};
}

}  // namespace

void ResidencyManager::updateCentre(uint32_t level, double f_x, double f_y, uint32_t n,
                                    bool limit_step) {
  LevelCentre& c = centres_[level];
  const uint32_t t = info_.tile_size_px;
  double fx = f_x / levelScale(level) / t, fy = f_y / levelScale(level) / t;
  int64_t target_x = clipCentreTile(f_x / levelScale(level), t);  // eq. 4
  int64_t target_y = clipCentreTile(f_y / levelScale(level), t);
  c.prev_x = c.x;
  c.prev_y = c.y;
  if (!c.valid) {
    c = {true, target_x, target_y, target_x, target_y};
    return;
  }
  // Effective region: size floor(n / 2) around the centre; inside it nothing reloads.
  double half = std::floor(n / 2.0) / 2;
  bool outside = std::abs(fx - double(c.x)) > half || std::abs(fy - double(c.y)) > half;
  if (!outside) return;
  // A move of a whole region or more is a jump, not a flight: the regions in between share no
  // tile with the destination, so walking through them would only load what is never shown.
  const bool jump = std::max(std::abs(target_x - c.x), std::abs(target_y - c.y)) >= int64_t(n);
  double step = limit_step && !jump ? options_.max_centre_step_tiles : 1e18;
  auto approach = [&](int64_t from, int64_t to) {
    int64_t delta = to - from;
    int64_t limit = int64_t(std::max(1.0, step));
    return from + std::clamp(delta, -limit, limit);
  };
  c.x = approach(c.x, target_x);
  c.y = approach(c.y, target_y);
}

void ResidencyManager::addWanted(const TileId& tile, int cls, double distance, bool prefetch,
                                 bool ahead) {
  // Tiles the view will show soon rank after every tile it shows now, at any level, within
  // the same class: they load as urgently, but a fast pan spends the upload budget on the
  // screen first instead of on coarse tiles far ahead of it.
  double priority = cls * kClassStride + (ahead ? kClassStride / 2 : 0) +
                    (info_.level_count - 1 - tile.level) * kLevelStride +
                    std::min(distance, kLevelStride - 1);
  auto [it, inserted] = wanted_index_.try_emplace(tile, priority);
  if (!inserted) {
    if (priority >= it->second) return;
    it->second = priority;
  }
  plan_.wanted.push_back({tile, priority, prefetch, uint32_t(cls)});
}

double ResidencyManager::distanceFromCentre(const TileId& tile) const {
  const double span = levelScale(tile.level) * info_.tile_size_px;
  const double dx = (tile.x + 0.5) * span - frame_.fp.centre_x;
  const double dy = (tile.y + 0.5) * span - frame_.fp.centre_y;
  return std::sqrt(dx * dx + dy * dy) / span;
}

void ResidencyManager::addRect(uint32_t level, const TileRect& rect, int cls, bool prefetch,
                               bool ahead) {
  TileRect r = intersect(rect, gridRect(level));
  for (int64_t y = r.y0; y < r.y1; ++y)
    for (int64_t x = r.x0; x < r.x1; ++x) {
      TileId tile{image_, level, uint32_t(x), uint32_t(y)};
      addWanted(tile, cls, distanceFromCentre(tile), prefetch, ahead);
    }
}

void ResidencyManager::addVisibleOrtho() {
  const Footprint& fp = frame_.fp;
  const uint32_t t = info_.tile_size_px;
  for (uint32_t l = frame_.desired; l < info_.level_count; ++l) {
    TileRect under = intersect(tilesUnder(fp.x0, fp.y0, fp.x1, fp.y1, l, t), gridRect(l));
    addRect(l, under, 1, false);
    if (l == frame_.desired)
      for (int64_t y = under.y0; y < under.y1; ++y)
        for (int64_t x = under.x0; x < under.x1; ++x)
          plan_.visible.push_back({image_, l, uint32_t(x), uint32_t(y)});
  }
}

void ResidencyManager::addVisiblePerspective(const View& view) {
  // Quadtree refinement: split a visible tile while it is coarser than its nearest point needs.
  const Footprint& fp = frame_.fp;
  const uint32_t t = info_.tile_size_px;
  const uint32_t coarsest = info_.level_count - 1;
  std::vector<TileId> stack;
  TileRect top = gridRect(coarsest);
  for (int64_t y = top.y0; y < top.y1; ++y)
    for (int64_t x = top.x0; x < top.x1; ++x)
      stack.push_back({image_, coarsest, uint32_t(x), uint32_t(y)});
  constexpr size_t kMaxVisibleTiles = 4096;
  while (!stack.empty()) {
    TileId tile = stack.back();
    stack.pop_back();
    addWanted(tile, 1, distanceFromCentre(tile), false, false);
    uint32_t needed = requiredLevelForTile(view, info_, tile, frame_.desired);
    if (tile.level == 0 || needed >= tile.level || plan_.visible.size() > kMaxVisibleTiles) {
      plan_.visible.push_back(tile);
      continue;
    }
    TileRect children =
        intersect(intersect({int64_t(tile.x) * 2, int64_t(tile.y) * 2, int64_t(tile.x) * 2 + 2,
                             int64_t(tile.y) * 2 + 2},
                            tilesUnder(fp.x0, fp.y0, fp.x1, fp.y1, tile.level - 1, t)),
                  gridRect(tile.level - 1));
    for (int64_t y = children.y0; y < children.y1; ++y)
      for (int64_t x = children.x0; x < children.x1; ++x)
        stack.push_back({image_, tile.level - 1, uint32_t(x), uint32_t(y)});
  }
}

bool ResidencyManager::jumpedThisFrame() const {
  const double span = levelScale(frame_.desired) * info_.tile_size_px;
  const double step_x = frame_.fp.centre_x - frame_.prev_centre_x;
  const double step_y = frame_.fp.centre_y - frame_.prev_centre_y;
  return std::max(std::abs(step_x), std::abs(step_y)) >= frame_.n * span;
}

void ResidencyManager::addLookahead() {
  // A move of a whole region or more in one frame is a jump, not a velocity.
  const Footprint& fp = frame_.fp;
  const double step_x = fp.centre_x - frame_.prev_centre_x;
  const double step_y = fp.centre_y - frame_.prev_centre_y;
  const bool moving = step_x != 0 || step_y != 0;
  if (!moving || jumpedThisFrame()) return;
  const double ahead_x = step_x * options_.lookahead_frames;
  const double ahead_y = step_y * options_.lookahead_frames;
  const double x0 = std::min(fp.x0, fp.x0 + ahead_x), x1 = std::max(fp.x1, fp.x1 + ahead_x);
  const double y0 = std::min(fp.y0, fp.y0 + ahead_y), y1 = std::max(fp.y1, fp.y1 + ahead_y);
  for (uint32_t l = frame_.desired; l < info_.level_count; ++l)
    addRect(l, tilesUnder(x0, y0, x1, y1, l, info_.tile_size_px), 1, false, /*ahead=*/true);
}

TileRect ResidencyManager::addClipRegions() {
  const LevelCentre& c = centres_[frame_.desired];
  const TileRect clip = clipRegionAround(c.x, c.y, frame_.n);
  for (uint32_t l = frame_.desired; l < info_.level_count; ++l) {
    TileRect region = coarsen(clip, l - frame_.desired);
    TileRect clipped = intersect(region, gridRect(l));
    addRect(l, clipped, 2, false);
    if (!clipped.empty()) plan_.clip_regions.push_back({l, clipped});
    uint32_t m = options_.keep_margin_tiles;
    keep_rects_[l] = {region.x0 - m, region.y0 - m, region.x1 + m, region.y1 + m};
  }
  for (const TileId& tile : plan_.visible) {
    TileRect& keep = keep_rects_[tile.level];
    if (keep.empty()) keep = {tile.x, tile.y, int64_t(tile.x) + 1, int64_t(tile.y) + 1};
    keep = {std::min<int64_t>(keep.x0, tile.x), std::min<int64_t>(keep.y0, tile.y),
            std::max<int64_t>(keep.x1, tile.x + 1), std::max<int64_t>(keep.y1, tile.y + 1)};
  }
  return clip;
}

void ResidencyManager::addPrefetch(const TileRect& clip) {
  const uint32_t desired = frame_.desired;
  if (frame_.first_frame) {
    addRect(desired, {clip.x0 - 1, clip.y0 - 1, clip.x1 + 1, clip.y0}, 3, true);
    addRect(desired, {clip.x0 - 1, clip.y1, clip.x1 + 1, clip.y1 + 1}, 3, true);
    addRect(desired, {clip.x0 - 1, clip.y0, clip.x0, clip.y1}, 3, true);
    addRect(desired, {clip.x1, clip.y0, clip.x1 + 1, clip.y1}, 3, true);
    return;
  }
  // A jump says nothing about where the view goes next: a row or column beyond the new region
  // would be loaded before the loader runs out of work (up to 2n tiles, a tenth of an FHD
  // region's load), for no better chance of being shown than any other.
  if (jumpedThisFrame()) return;
  const double span = levelScale(desired) * info_.tile_size_px;
  const Footprint& fp = frame_.fp;
  int64_t cross_x =
      int64_t(std::floor(fp.centre_x / span)) - int64_t(std::floor(frame_.prev_centre_x / span));
  int64_t cross_y =
      int64_t(std::floor(fp.centre_y / span)) - int64_t(std::floor(frame_.prev_centre_y / span));
  if (cross_x > 0) addRect(desired, {clip.x1, clip.y0, clip.x1 + 1, clip.y1}, 3, true);
  if (cross_x < 0) addRect(desired, {clip.x0 - 1, clip.y0, clip.x0, clip.y1}, 3, true);
  if (cross_y > 0) addRect(desired, {clip.x0, clip.y1, clip.x1, clip.y1 + 1}, 3, true);
  if (cross_y < 0) addRect(desired, {clip.x0, clip.y0 - 1, clip.x1, clip.y0}, 3, true);
}

void ResidencyManager::finishPlan() {
  // Keep only the best priority per tile, sorted.
  std::sort(plan_.wanted.begin(), plan_.wanted.end(),
            [](const TileRequest& a, const TileRequest& b) { return a.priority < b.priority; });
  plan_.wanted.erase(
      std::remove_if(plan_.wanted.begin(), plan_.wanted.end(),
                     [&](const TileRequest& r) { return wanted_index_.at(r.id) != r.priority; }),
      plan_.wanted.end());

  const Footprint& fp = frame_.fp;
  plan_.motion.centre_x = fp.centre_x;
  plan_.motion.centre_y = fp.centre_y;
  plan_.motion.motion_x = frame_.first_frame ? 0 : fp.centre_x - frame_.prev_centre_x;
  plan_.motion.motion_y = frame_.first_frame ? 0 : fp.centre_y - frame_.prev_centre_y;
  for (uint32_t l = 0; l < info_.level_count; ++l)
    if (!keep_rects_[l].empty())
      plan_.motion.keep_regions.push_back(
          {image_, l, keep_rects_[l].x0, keep_rects_[l].y0, keep_rects_[l].x1, keep_rects_[l].y1});
}

const ResidencyPlan& ResidencyManager::plan(const View& view) {
  // A held view (the viewer at rest, a flight between jumps) would otherwise rebuild and sort
  // the same wanted set every frame on the render thread.
  const bool same_view = has_last_view_ && sameView(view, last_view_);
  if (same_view && settled_) return plan_;
  const uint32_t coarsest = info_.level_count - 1;
  centres_before_.assign(centres_.begin(), centres_.end());
  frame_.fp = footprintOf(view, info_);
  frame_.desired = frame_.fp.desired_level;
  frame_.n = clipRegionTiles(view.viewportWidth(), view.viewportHeight(), info_.tile_size_px);
  // The last frame's centre, for the motion, the lookahead and the prefetch.
  frame_.prev_centre_x = last_centre_x_;
  frame_.prev_centre_y = last_centre_y_;
  frame_.first_frame = !centres_[frame_.desired].valid;
  for (uint32_t l = frame_.desired; l <= coarsest; ++l)
    updateCentre(l, frame_.fp.centre_x, frame_.fp.centre_y, frame_.n, true);
  // Levels finer than the desired one lose their centres so a later zoom-in starts afresh.
  for (uint32_t l = 0; l < frame_.desired; ++l) centres_[l].valid = false;

  plan_ = {};
  plan_.desired_level = frame_.desired;
  wanted_index_.clear();
  keep_rects_.assign(info_.level_count, TileRect{});

  // Class 0: the coarsest level, always resident so every texel is always covered.
  addRect(coarsest, gridRect(coarsest), 0, false);
  // Class 1: what the view shows, at the level it needs, and everything coarser beneath it;
  // then where an orthographic view will be `lookahead_frames` from now, and everything it
  // sweeps on the way, with the coarser tiles beneath (a child goes up only after its parent).
  if (view.kind == View::Kind::kOrtho)
    addVisibleOrtho();
  else
    addVisiblePerspective(view);
  if (view.kind == View::Kind::kOrtho && !frame_.first_frame && options_.lookahead_frames > 0)
    addLookahead();
  // Class 2: the clip region at the desired level (eq. 3-4, with hysteresis), and at coarser
  // levels the tiles under it: from the start level of eq. 7 on that is a single tile.
  const TileRect clip = addClipRegions();
  // Class 3: direction-based prefetch (Luo & Duan, section 3.3): when the view centre
  // crosses a tile boundary, the next column or row beyond the clip region in that direction.
  if (options_.prefetch) addPrefetch(clip);

  finishPlan();
  last_centre_x_ = frame_.fp.centre_x;
  last_centre_y_ = frame_.fp.centre_y;
  // Settled: this frame saw no motion (the footprint centre was the last frame's) and moved
  // no centre, so planning the same view again repeats every step above.
  bool centres_moved = false;
  for (uint32_t l = 0; l <= coarsest; ++l)
    centres_moved = centres_moved || centres_[l].valid != centres_before_[l].valid ||
                    centres_[l].x != centres_before_[l].x || centres_[l].y != centres_before_[l].y;
  settled_ = same_view && !centres_moved;
  last_view_ = view;
  has_last_view_ = true;
  ++plans_computed_;
  return plan_;
}

bool ResidencyManager::isWanted(const TileId& tile) const {
  return wanted_index_.count(tile) > 0;
}

double ResidencyManager::priorityOf(const TileId& tile) const {
  auto it = wanted_index_.find(tile);
  return it == wanted_index_.end() ? 1e300 : it->second;
}

bool ResidencyManager::isKept(const TileId& tile) const {
  if (tile.image != image_ || tile.level >= keep_rects_.size()) return false;
  if (tile.level + 1 == info_.level_count) return true;
  return keep_rects_[tile.level].contains(tile.x, tile.y) || isWanted(tile);
}

void ResidencyManager::measureCoverage(const std::function<bool(const TileId&)>& resident,
                                       FrameReport& report) const {
  report.desired_level = plan_.desired_level;
  size_t at_desired = 0;
  bool all_covered = true;
  uint32_t finest_full = plan_.desired_level;
  for (const TileId& tile : plan_.visible) {
    if (resident(tile)) {
      ++at_desired;
      continue;
    }
    // The finest resident ancestor covers this tile's area.
    TileId ancestor = tile;
    bool covered = false;
    while (ancestor.level + 1 < info_.level_count) {
      ancestor = {ancestor.image, ancestor.level + 1, ancestor.x / 2, ancestor.y / 2};
      if (resident(ancestor)) {
        covered = true;
        break;
      }
    }
    if (!covered) all_covered = false;
    finest_full = std::max(finest_full, covered ? ancestor.level : uint32_t(info_.level_count));
  }
  report.coverage_desired =
      plan_.visible.empty() ? 1.0 : double(at_desired) / double(plan_.visible.size());
  report.fully_covered = all_covered;
  report.finest_full_level = std::min(finest_full, info_.level_count - 1);
}

}  // namespace tessera::detail
