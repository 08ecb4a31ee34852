// ptm's texel walk: the parts that are not templates (ptm_walk.h).
#include "ptm/ptm_walk.h"

#include <fmt/format.h>

namespace tessera::detail::ptm {

namespace {

// Returns false when a child texel's block falls outside the parent tile: the caller passed
// geometry that does not come from one image's quadtree.
bool mapAxis(uint32_t child_px, uint32_t parent_px, uint64_t offset, AxisMap& map) {
  map.parent.resize(child_px);
  map.neighbour.resize(child_px);
  map.second.resize(child_px);
  map.full.resize(child_px);
  map.derived.resize(child_px);
  for (uint32_t i = 0; i < child_px; ++i) {
    const uint64_t u = offset + i;
    const uint64_t j = u >> 1;
    if (j >= parent_px) return false;
    const bool second = (u & 1) != 0;
    map.parent[i] = uint32_t(j);
    // Bilinear upsampling weights the parent texel on the child's side of its block.
    map.neighbour[i] =
        second ? uint32_t(std::min<uint64_t>(j + 1, parent_px - 1)) : uint32_t(j == 0 ? 0 : j - 1);
    map.second[i] = second;
    // A block whose first child lies before the tile (odd border) is coded texel by texel.
    map.full[i] = second ? i > 0 : i + 1 < child_px;
    map.derived[i] = second && i > 0;
  }
  return true;
}

// The parent bilinearly upsampled to every child texel, times 16, plus 6: a floor-average
// parent sits 0.375 below its block's mean. Per child row, the two parent rows are blended
// first at the parent's resolution, `blend` = 3 P + Pv over the columns the row reads (a loop
// the compiler vectorises), so that each child texel costs 3 blend[j] + blend[jn] + 6, the
// same 9 P + 3 Ph + 3 Pv + Pd + 6.
template <uint32_t kChannels>
void upsampleParent(const ImageView& parent, const AxisMap& columns, const AxisMap& rows,
                    int16_t* out, std::vector<int16_t>& blend) {
  const uint32_t width = uint32_t(columns.parent.size()), height = uint32_t(rows.parent.size());
  // Every neighbour column lies between the first and last child's parent or neighbour.
  const uint32_t first = std::min(columns.parent.front(), columns.neighbour.front());
  const uint32_t last = std::max(columns.parent.back(), columns.neighbour.back());
  const size_t span = size_t(last - first + 1) * kChannels;
  blend.resize(span);
  int16_t* const blended = blend.data();
  for (uint32_t y = 0; y < height; ++y) {
    const uint8_t* parent_row = parent.row(rows.parent[y]) + size_t(first) * kChannels;
    const uint8_t* parent_near = parent.row(rows.neighbour[y]) + size_t(first) * kChannels;
    for (size_t i = 0; i < span; ++i) blended[i] = int16_t(3 * parent_row[i] + parent_near[i]);
    for (uint32_t x = 0; x < width; ++x) {
      const int16_t* p = blended + size_t(columns.parent[x] - first) * kChannels;
      const int16_t* pn = blended + size_t(columns.neighbour[x] - first) * kChannels;
      for (uint32_t c = 0; c < kChannels; ++c) *out++ = int16_t(3 * p[c] + pn[c] + 6);
    }
  }
}

// Coder 6's error plane in `state`, sized to the tile; null for the other coders.
uint16_t* errorPlane(PtmCoder coder, uint32_t width, uint32_t height, PtmState& state) {
  if (!isErrorActivityCoder(coder)) return nullptr;
  state.errors.resize(size_t(width) * height);
  return state.errors.data();
}

// The parent bilinearly upsampled to every child texel into `out`, and `detail` sized to match.
void upsample(uint32_t channels, const ImageView& parent, const AxisMap& columns,
              const AxisMap& rows, std::vector<int16_t>& out, std::vector<int16_t>& detail,
              std::vector<int16_t>& blend) {
  out.resize(columns.parent.size() * rows.parent.size() * channels);
  detail.resize(out.size());
  switch (channels) {
    case 1: return upsampleParent<1>(parent, columns, rows, out.data(), blend);
    case 2: return upsampleParent<2>(parent, columns, rows, out.data(), blend);
    case 3: return upsampleParent<3>(parent, columns, rows, out.data(), blend);
    default: return upsampleParent<4>(parent, columns, rows, out.data(), blend);
  }
}

// Maps both axes, or explains why the parent does not fit.
Result<void> mapParent(const ImageView& parent_view, const ParentTexels& parent, uint32_t width,
                       uint32_t height, uint32_t channels, AxisMap& columns, AxisMap& rows) {
  if (parent_view.channels != channels)
    return fail(ErrorCode::kInvalidArgument, fmt::format("ptm: parent has {} channels, tile {}",
                                                         parent_view.channels, channels));
  if (parent.quadrant_x > 1 || parent.quadrant_y > 1 ||
      !mapAxis(width, parent_view.width_px,
               uint64_t(parent.quadrant_x) * parent.tile_size_px + parent.border_px, columns) ||
      !mapAxis(height, parent_view.height_px,
               uint64_t(parent.quadrant_y) * parent.tile_size_px + parent.border_px, rows))
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("ptm: a {}x{} tile in quadrant ({},{}) at tile size {}, border {} "
                    "does not fit its {}x{} parent",
                    width, height, parent.quadrant_x, parent.quadrant_y, parent.tile_size_px,
                    parent.border_px, parent_view.width_px, parent_view.height_px));
  return {};
}

}  // namespace

SymbolCounts countSymbols(const Walk& walk) {
  const size_t total = size_t(walk.width) * walk.height;
  if (walk.parent == nullptr) return {total, 0};
  size_t derived_columns = 0, derived_rows = 0;
  for (uint8_t d : walk.columns->derived) derived_columns += d;
  for (uint8_t d : walk.rows->derived) derived_rows += d;
  return {total - derived_columns * derived_rows, derived_columns * derived_rows};
}

Result<Walk> prepareWalk(uint8_t* texels, uint32_t width, uint32_t height, uint32_t channels,
                         const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                         const int8_t* ls_weights, PtmState& state, AxisMap& columns, AxisMap& rows,
                         bool planes) {
  const bool has_parent = predictor != Predictor::kRoot;
  if (has_parent)
    TESSERA_TRY(mapParent(parent->texels, *parent, width, height, channels, columns, rows));
  const bool estimates = predictor == Predictor::kParentCorrected ||
                         (predictor == Predictor::kLeastSquares &&
                          (ls_weights == nullptr || usesEstimate(ls_weights, channels)));
  const bool upsampled = estimates && planes;
  if (upsampled)
    upsample(channels, parent->texels, columns, rows, state.upsampled, state.detail,
             state.parent_blend);
  return Walk{texels,
              width,
              height,
              has_parent ? &parent->texels : nullptr,
              &columns,
              &rows,
              upsampled ? state.upsampled.data() : nullptr,
              upsampled ? state.detail.data() : nullptr,
              errorPlane(coder, width, height, state),
              ls_weights,
              estimates};
}

}  // namespace tessera::detail::ptm
