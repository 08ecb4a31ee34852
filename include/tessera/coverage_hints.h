#pragma once
/// \file
/// Average coverage hints of a scene archive (Marvie & Bouatouch, seed 003 part II;
/// docs/scenes.md, "Coverage hints"; docs/format.md, "Coverage hints"): a regular grid of view
/// cells over the scene's ground, and per cell the textures seen from it with the share of the
/// cell's sampled view (8 positions x 6 cube faces) their objects cover. Plain data; the
/// builder computes it, SceneArchive::readCoverageHints reads it, SceneStreamer uses it to
/// rank and size texture loads before per-frame feedback exists.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

namespace tessera {

/// One texture seen from a cell.
struct CoverageHint {
  uint32_t texture = 0;  ///< texture index, < the scene's texture count
  /// Quantised share of the cell's sampled sphere of directions (every sampled pixel weighted
  /// by its solid angle) covered by objects using the texture: q / 65535, q in 1..65535. Any
  /// texture seen at all has q >= 1.
  uint16_t coverage_q = 1;
  double coverage() const { return coverage_q / 65535.0; }
  friend bool operator==(const CoverageHint&, const CoverageHint&) = default;
};

/// The hints of a whole scene. Cells are squares of `cell_size` on the two axes other than
/// `up_axis` (u is the lower-numbered axis, v the other), cell (i, j) covering
/// [origin_u + i * cell_size, + cell_size) x [origin_v + j * cell_size, + cell_size), numbered
/// j * cells_u + i.
struct CoverageHints {
  uint32_t up_axis = 1;  ///< 0 = x, 1 = y, 2 = z
  uint32_t cells_u = 1, cells_v = 1;
  float origin_u = 0, origin_v = 0;
  float cell_size = 1;  ///< world units, > 0
  /// The two sampled eye heights along up_axis (world coordinates, low <= high).
  float eye_low = 0, eye_high = 0;
  uint32_t resolution_px = 64;        ///< pixels per cube-face side
  uint32_t positions_per_cell = 8;    ///< eye positions sampled per cell
  uint32_t directions = 6;            ///< views per position (cube faces, 90 degrees each)
  uint32_t texture_count = 0;         ///< the scene's
  std::vector<uint32_t> cell_first;   ///< cells + 1 entries: cell c is [cell_first[c], [c + 1])
  std::vector<CoverageHint> entries;  ///< per cell, textures in increasing order

  uint32_t cellCount() const { return cells_u * cells_v; }
  std::span<const CoverageHint> cell(uint32_t index) const {
    return std::span(entries).subspan(cell_first[index], cell_first[index + 1] - cell_first[index]);
  }
  uint32_t axisU() const { return up_axis == 0 ? 1 : 0; }
  uint32_t axisV() const { return up_axis == 2 ? 1 : 2; }
  /// The cell holding a world point's ground position, clamped to the grid when within one
  /// cell of it; -1 further out (hints of a far cell say little about the point).
  int64_t cellAt(const double point[3]) const {
    const double fu = (point[axisU()] - origin_u) / cell_size;
    const double fv = (point[axisV()] - origin_v) / cell_size;
    if (!(fu >= -1 && fv >= -1 && fu < cells_u + 1.0 && fv < cells_v + 1.0)) return -1;
    const int64_t i = std::clamp<int64_t>(int64_t(std::floor(fu)), 0, cells_u - 1);
    const int64_t j = std::clamp<int64_t>(int64_t(std::floor(fv)), 0, cells_v - 1);
    return j * cells_u + i;
  }
  friend bool operator==(const CoverageHints&, const CoverageHints&) = default;
};

}  // namespace tessera
