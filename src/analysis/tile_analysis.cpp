#include "analysis/tile_analysis.h"

#include <algorithm>
#include <cmath>

#include "procedural/kernel.h"
#include "procedural/row_kernel.h"

namespace tessera::detail {

uint32_t DetailMap::finestLevelIn(const BoxPx& box) const {
  if (cell_px == 0 || columns == 0 || rows == 0) return 0;
  auto cell = [&](double v, uint32_t count) {
    return int64_t(std::clamp(std::floor(v / cell_px), -1.0, double(count)));
  };
  const int64_t x0 = cell(box.x0, columns), x1 = cell(box.x1, columns);
  const int64_t y0 = cell(box.y0, rows), y1 = cell(box.y1, rows);
  uint32_t finest = 255;
  for (int64_t y = y0; y <= y1; ++y) {
    for (int64_t x = x0; x <= x1; ++x) {
      if (x < 0 || y < 0 || x >= columns || y >= rows) return 0;  // outside: every level
      finest = std::min<uint32_t>(finest, finest_level[size_t(y) * columns + size_t(x)]);
      if (finest == 0) return 0;
    }
  }
  return finest;
}

bool isNegligibleInstance(const BrushInstance& instance, const AnalysisRules& rules) {
  if (rules.small_instance_texels <= 0) return false;
  // Small at the finest level stored over the instance means small at every stored level
  // there, so it is dropped from all of them together: no level shows it while another does
  // not (seed 001, section 2.1).
  const uint32_t finest = rules.detail ? rules.detail->finestLevelIn(instanceBounds(instance)) : 0;
  const double diameter = 2.0 * double(instance.radius_px) * double(instance.scale);
  return diameter < rules.small_instance_texels * std::ldexp(1.0, int(finest));
}

namespace {

struct Span {
  int64_t i_lo = 0, i_hi = 0, j_lo = 0, j_hi = 0;
  uint64_t texels() const { return uint64_t(i_hi - i_lo) * uint64_t(j_hi - j_lo); }
};

}  // namespace

Result<TileAnalysis> analyseTile(const BrushSet& brushes, const TileGeometry& tile,
                                 std::span<const BrushInstance> candidates,
                                 const AnalysisRules& rules) {
  const BrushSet::Impl& set = brushes.impl();
  const int64_t level_w = std::max<int64_t>(
      1, (int64_t(tile.image_width_px) + (int64_t(1) << tile.level) - 1) >> tile.level);
  const int64_t level_h = std::max<int64_t>(
      1, (int64_t(tile.image_height_px) + (int64_t(1) << tile.level) - 1) >> tile.level);
  const int64_t side = tile.sidePx();
  const int64_t x0 = levelTexel(tile.x, tile.tile_size_px, tile.border_px, 0);
  const int64_t y0 = levelTexel(tile.y, tile.tile_size_px, tile.border_px, 0);
  // The stored texels whose level texel is inside the level (the compositor's valid rectangle);
  // the others repeat them.
  const int64_t i0 = std::clamp<int64_t>(-x0, 0, side),
                i1 = std::clamp<int64_t>(level_w - x0, i0, side);
  const int64_t j0 = std::clamp<int64_t>(-y0, 0, side),
                j1 = std::clamp<int64_t>(level_h - y0, j0, side);
  const int64_t width = i1 - i0;
  std::vector<uint8_t> covered(size_t(width) * size_t(j1 - j0), 0);
  std::vector<uint8_t> height_values, slope_values;
  auto layerValues = [&](MaskSource source) -> const std::vector<uint8_t>& {
    std::vector<uint8_t>& cache = source == MaskSource::kHeight ? height_values : slope_values;
    if (cache.empty()) {
      const LayerPyramid& layer = source == MaskSource::kHeight ? set.height : set.slope;
      cache.resize(covered.size());
      for (int64_t j = j0; j < j1; ++j)
        for (int64_t i = i0; i < i1; ++i)
          cache[size_t(j - j0) * size_t(width) + size_t(i - i0)] = sampleLayer(
              layer, set.texture_width_px, set.texture_height_px, tile.level, x0 + i, y0 + j);
    }
    return cache;
  };

  TileAnalysis analysis;
  std::vector<uint8_t> row_alpha;
  std::vector<bool> keep(candidates.size(), false);
  std::vector<TileClip> clips(candidates.size());
  // From the top down: an instance contributes when some texel where it draws is not yet
  // covered by an opaque normal-blend texel above it (such a texel replaces whatever lies
  // below, exactly: docs/procedural.md, "Culling"). Then its own opaque texels cover.
  for (size_t k = candidates.size(); k-- > 0;) {
    const BrushInstance& instance = candidates[k];
    if (isNegligibleInstance(instance, rules)) {
      ++analysis.small;
      continue;
    }
    TESSERA_ASSIGN_OR_RETURN(InstanceSetup setup, setupInstance(set, instance, tile.level));
    Span span{std::max<int64_t>(i0, setup.x_c - setup.reach - x0),
              std::min<int64_t>(i1, setup.x_c + setup.reach + 1 - x0),
              std::max<int64_t>(j0, setup.y_c - setup.reach - y0),
              std::min<int64_t>(j1, setup.y_c + setup.reach + 1 - y0)};
    if (span.i_lo >= span.i_hi || span.j_lo >= span.j_hi) {
      ++analysis.covered;  // touches no texel of this tile
      continue;
    }
    const std::vector<uint8_t>* mask =
        setup.brush->mask == MaskSource::kNone ? nullptr : &layerValues(setup.brush->mask);
    const bool can_cover = setup.brush->blend == BlendMode::kNormal;
    // Only texels not yet covered are sampled; those where the instance draws bound its clip.
    int64_t vis_i0 = INT64_MAX, vis_i1 = INT64_MIN, vis_j0 = INT64_MAX, vis_j1 = INT64_MIN;
    for (int64_t j = span.j_lo; j < span.j_hi; ++j) {
      const RowSpan row = instanceRowSpan(setup, y0 + j);
      const int64_t first = std::max(row.first, x0 + span.i_lo);
      const int64_t last = std::min(row.last, x0 + span.i_hi - 1);
      const size_t base = size_t(j - j0) * size_t(width) - size_t(x0 + i0);
      for (int64_t run = first; run <= last;) {
        if (covered[base + size_t(run)]) {
          ++run;
          continue;
        }
        int64_t run_end = run;
        while (run_end < last && !covered[base + size_t(run_end + 1)]) ++run_end;
        row_alpha.resize(size_t(run_end - run + 1));
        instanceRowAlpha(setup, y0 + j, run, run_end, row_alpha.data());
        for (int64_t x = run; x <= run_end; ++x) {
          uint32_t alpha = row_alpha[size_t(x - run)];
          const size_t index = base + size_t(x);
          if (alpha != 0 && mask) alpha = div255(alpha * setup.brush->mask_lut[(*mask)[index]]);
          if (alpha == 0) continue;
          const int64_t i = x - x0;
          vis_i0 = std::min(vis_i0, i), vis_i1 = std::max(vis_i1, i);
          vis_j0 = std::min(vis_j0, j), vis_j1 = std::max(vis_j1, j);
          if (can_cover && alpha == 255) covered[index] = 1;
        }
        run = run_end + 1;
      }
    }
    if (vis_i1 >= vis_i0) {
      keep[k] = true;
      clips[k] = {uint16_t(vis_i0), uint16_t(vis_j0), uint16_t(vis_i1 + 1), uint16_t(vis_j1 + 1)};
    } else {
      ++analysis.covered;
    }
  }
  for (size_t k = 0; k < candidates.size(); ++k) {
    if (!keep[k]) continue;
    analysis.kept.push_back(candidates[k]);
    analysis.clips.push_back(clips[k]);
    // The compositor visits the clip's texels of the instance's row spans: at most its area.
    analysis.visited_texels += uint64_t(clips[k].x1 - clips[k].x0) * (clips[k].y1 - clips[k].y0);
  }
  analysis.estimated_ms = rules.cost.estimateMs(analysis.kept.size(), analysis.visited_texels);
  analysis.within_budget = analysis.estimated_ms <= rules.tile_budget_ms;
  return analysis;
}

}  // namespace tessera::detail
