#include "adaptive.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <fmt/format.h>

#include <tessera/archive.h>

namespace tessera::detail {

namespace {

/// A level already requested stays requested until its missing bytes exceed its budget by
/// this factor: the estimate swings as reads come and go, and dropping a level cancels its
/// reads in flight.
constexpr double kKeepFactor = 2.0;

bool sameView(const View& a, const View& b) {
  if (a.kind != b.kind || a.image != b.image) return false;
  if (a.kind == View::Kind::kOrtho) {
    const OrthoView &x = a.ortho, &y = b.ortho;
    return x.centre_x == y.centre_x && x.centre_y == y.centre_y &&
           x.texels_per_pixel == y.texels_per_pixel && x.viewport_w == y.viewport_w &&
           x.viewport_h == y.viewport_h && x.rotation_rad == y.rotation_rad;
  }
  const PerspectiveView &x = a.perspective, &y = b.perspective;
  return x.eye_x == y.eye_x && x.eye_y == y.eye_y && x.eye_z == y.eye_z && x.yaw_rad == y.yaw_rad &&
         x.pitch_rad == y.pitch_rad && x.fov_y_rad == y.fov_y_rad && x.viewport_w == y.viewport_w &&
         x.viewport_h == y.viewport_h;
}

}  // namespace

AdaptiveScheduler::AdaptiveScheduler(const AdaptiveOptions& options, uint32_t level_count,
                                     uint64_t tile_bytes, uint64_t cache_budget_bytes)
    : options_(options),
      level_count_(std::max(1u, level_count)),
      tile_bytes_(tile_bytes),
      cache_budget_bytes_(cache_budget_bytes) {}

bool AdaptiveScheduler::egressAllows(uint64_t payload_bytes) const {
  const EgressBudget& egress = options_.egress;
  const uint64_t bytes = prefetch_bytes_ + payload_bytes;
  const uint64_t tiles = prefetch_tiles_ + 1;
  if (egress.byte_factor > 0 &&
      double(bytes) > std::max(0.0, egress.byte_factor - 1.0) * double(view_bytes_))
    return false;
  if (egress.request_factor > 0 &&
      double(tiles) > std::max(0.0, egress.request_factor - 1.0) * double(view_tiles_))
    return false;
  if (egress.max_prefetch_bytes && bytes > egress.max_prefetch_bytes) return false;
  if (egress.max_prefetch_requests && tiles > egress.max_prefetch_requests) return false;
  return true;
}

void AdaptiveScheduler::countEgress(const TileRequest& request, uint64_t payload_bytes) {
  if (!counted_.insert(request.id).second) return;
  if (request.urgency <= 1) {
    view_bytes_ += payload_bytes;
    ++view_tiles_;
  } else {
    prefetch_bytes_ += payload_bytes;
    ++prefetch_tiles_;
  }
}

bool AdaptiveScheduler::observe(const View& view, Clock::time_point now) {
  // A new view counts as a change: a first picture is refined after n seconds like any other.
  if (!have_view_ || !sameView(view, last_view_)) last_change_ = now;
  have_view_ = true;
  last_view_ = view;
  return std::chrono::duration<double>(now - last_change_).count() >= options_.still_after_s;
}

void AdaptiveScheduler::schedule(const View& view, Clock::time_point now, const LinkEstimate& link,
                                 std::span<const TileRequest> wanted,
                                 const std::function<TileFacts(const TileId&)>& facts,
                                 std::vector<TileRequest>& requests, FrameReport& report) {
  const bool still = observe(view, now);
  const AdaptiveBudget& budget = still ? options_.still : options_.moving;
  const uint64_t memory_budget = budget.memory_bytes
                                     ? std::min(budget.memory_bytes, cache_budget_bytes_)
                                     : cache_budget_bytes_;
  LinkEstimate estimate = link;
  if (estimate.reads == 0) estimate.bytes_per_s = options_.assumed_bytes_per_s;
  const double byte_budget = budget.level_time_limit_s > 0
                                 ? estimate.bytesWithin(budget.level_time_limit_s)
                                 : std::numeric_limits<double>::infinity();
  const uint32_t coarsest = level_count_ - 1;

  // Per level, over the tiles the view shows (urgency 0-1): payload bytes still to be
  // transferred (neither held nor on their way) and decoded bytes once all are held.
  missing_bytes_.assign(level_count_, 0);
  level_memory_.assign(level_count_, 0);
  std::vector<bool> level_shown(level_count_, false);
  uint64_t held_other = 0;  // held tiles of the rest of the regions, at any level
  for (const TileRequest& request : wanted) {
    const uint32_t level = std::min(request.id.level, coarsest);
    const TileFacts f = facts(request.id);
    if (request.urgency <= 1) {
      if (f.payload_known) countEgress(request, f.payload_bytes);
      level_shown[level] = true;
      level_memory_[level] += tile_bytes_;
      if (!f.held && !f.in_flight) missing_bytes_[level] += f.payload_bytes;
    } else if (f.held) {
      held_other += tile_bytes_;
    }
  }

  // Levels coarse to fine: the coarsest always, then each while it fits.
  const bool keep_last = last_level_ != UINT32_MAX && last_still_ == still;
  uint32_t level = coarsest;
  uint64_t memory = level_memory_[coarsest];
  for (uint32_t l = coarsest; l-- > 0;) {
    if (!level_shown[l]) break;
    const double allowed = keep_last && l >= last_level_ ? byte_budget * kKeepFactor : byte_budget;
    if (double(missing_bytes_[l]) > allowed) break;
    if (memory + level_memory_[l] > memory_budget) break;
    memory += level_memory_[l];
    level = l;
  }
  last_level_ = level;
  last_still_ = still;

  // Admit: every request of the view's tiles at accepted levels; then, once all of those have
  // arrived, the rest of the regions and the prefetch at accepted levels while the bytes on
  // their way and the memory fit. Over a link that is the bottleneck, a ring tile read beside
  // a visible one halves the visible one's share: the screen refines first.
  double on_the_way = 0;
  bool view_pending = false;
  for (const TileRequest& request : requests)
    if (request.urgency <= 1 && request.id.level >= level) {
      on_the_way += double(facts(request.id).payload_bytes);
      view_pending = true;
    }
  memory += held_other;
  uint64_t deferred = 0;
  uint64_t egress_deferred = 0;
  uint64_t requested_bytes = 0;
  size_t kept = 0;
  admitted_.clear();
  for (const TileRequest& request : requests) {
    bool admit = request.id.level >= level;
    const TileFacts f = facts(request.id);
    // Requests come coarse first, so a parent requested this frame is admitted by now.
    const bool parent_missing = !f.parent_ready && request.id.level < coarsest &&
                                !admitted_.count(Archive::parentTile(request.id));
    if (admit && request.urgency > 1) {
      admit = !parent_missing && !view_pending &&
              on_the_way + double(f.payload_bytes) <= byte_budget &&
              memory + tile_bytes_ <= memory_budget;
      // Egress: a tile requested before stays requested (its bytes are counted already).
      if (admit && !counted_.count(request.id) && !egressAllows(f.payload_bytes)) {
        admit = false;
        ++egress_deferred;
      }
      if (admit) {
        on_the_way += double(f.payload_bytes);
        memory += tile_bytes_;
      }
    }
    if (request.id.level == coarsest) admit = true;  // every texel always covered
    if (!admit) {
      ++deferred;
      continue;
    }
    // The view's own tiles are counted in their levels' memory; the parent the loader will
    // queue for one of them is not. Once counted, it serves its other children too.
    if (parent_missing) {
      memory += tile_bytes_;
      admitted_.insert(Archive::parentTile(request.id));
    }
    admitted_.insert(request.id);
    if (request.urgency > 1) countEgress(request, f.payload_bytes);
    requested_bytes += f.payload_bytes;
    requests[kept++] = request;
  }
  requests.resize(kept);

  report.adaptive = true;
  report.view_still = still;
  report.requested_level = level;
  report.budget_bytes =
      std::isfinite(byte_budget) ? uint64_t(std::llround(std::max(0.0, byte_budget))) : UINT64_MAX;
  report.memory_budget_bytes = memory_budget;
  report.memory_bytes = memory;
  report.requested_bytes = requested_bytes;
  report.deferred_tiles = deferred;
  report.egress_deferred_tiles = egress_deferred;
  report.view_bytes_total = view_bytes_;
  report.view_tiles_total = view_tiles_;
  report.prefetch_bytes_total = prefetch_bytes_;
  report.prefetch_tiles_total = prefetch_tiles_;
}

}  // namespace tessera::detail

namespace tessera {

Result<EgressBudget> parseEgressBudget(const std::string& spec) {
  if (spec == "default") return EgressBudget{};
  if (spec == "metered") return EgressBudget::metered();
  if (spec == "unbounded") return EgressBudget::unbounded();
  size_t used = 0;
  double factor = 0;
  try {
    factor = std::stod(spec, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != spec.size() || !std::isfinite(factor) || factor < 1.0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("egress budget '{}': expected default, metered, unbounded or a "
                            "factor of the view's bytes of at least 1 (e.g. 2.5)",
                            spec));
  EgressBudget budget;
  budget.byte_factor = factor;
  budget.request_factor = factor;
  return budget;
}

}  // namespace tessera
