#pragma once
// The synthetic source behind "synthetic:WxH[:seed[:channels]]": a deterministic, image-like
// generator for tests, demos and benchmarks at any size up to kMaxImageSidePx per side.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/result.h>

namespace tessera::detail {

/// A parsed synthetic source name.
struct SyntheticSpec {
  uint32_t width_px = 0;   ///< 1..kMaxImageSidePx
  uint32_t height_px = 0;  ///< 1..kMaxImageSidePx
  uint64_t seed = 1;       ///< any value; the same seed gives the same image on any machine
  uint32_t channels = 4;   ///< 3 (no-data flat black) or 4 (no-data transparent)
};

/// Parses "WxH[:seed[:channels]]" (the part after "synthetic:"). Errors name the whole source,
/// e.g. "synthetic:0x5: zero image dimensions": kInvalidArgument for bad syntax or channel
/// counts, kCorrupt for a zero side, kTooLarge for a side over kMaxImageSidePx.
[[nodiscard]] Result<SyntheticSpec> parseSyntheticSpec(const std::string& spec);

/// Paints fractal terrain coloured by elevation: flat deep sea (so uniform tiles occur), coast,
/// beaches, lowland greens varied by moisture, hills, rock and snow, hill shading, rivers,
/// streams, highways and roads as thin lines, and a no-data border outside an irregular "scan
/// footprint" near the edges. Integer arithmetic only, so the bytes are identical on every
/// machine and compiler. Any row range can be generated independently: rows depend only on
/// the spec and their index. Owned by one thread; it caches the coarse noise grid for the last
/// rows it generated, which makes consecutive bands cheap.
class SyntheticGenerator {
 public:
  explicit SyntheticGenerator(const SyntheticSpec& spec);
  const SyntheticSpec& spec() const { return spec_; }
  /// Writes rows [first_row, first_row + rows) into `out` (width_px * channels bytes per row,
  /// tightly packed). Requires the rows inside the image and `out` large enough.
  void generateRows(uint32_t first_row, uint32_t rows, std::span<uint8_t> out);

 private:
  struct Octave {
    int cell_shift = 0;  // cell side 2^cell_shift px
    int32_t amplitude = 0;
    uint32_t seed = 0;
  };
  enum Field { kElevation, kMoisture, kRiver, kStream, kHighway, kRoad, kFieldCount };

  /// Where a row's valid pixels lie: [left, valid_end), and whether the top and bottom
  /// borders, which vary along the row, reach it.
  struct RowFootprint {
    uint32_t left = 0;
    uint32_t valid_end = 0;
    bool near_top = false;
    bool near_bottom = false;
  };
  /// The top and bottom border depths at a grid cell's two ends (linear across the cell);
  /// zero where the row is not near that edge.
  struct CellBorders {
    int32_t top0 = 0, top1 = 0, bottom0 = 0, bottom1 = 0;
  };
  /// The line features (rivers, streams, roads) that may cross a grid cell: bit f of `mask`
  /// for field f, with its value * 16 at the cell's left end, its change per pixel and the
  /// threshold |value| * 16 stays under on the line.
  struct CellLines {
    uint32_t mask = 0;
    int32_t value[kFieldCount] = {};
    int32_t step[kFieldCount] = {};
    int32_t limit[kFieldCount] = {};
  };

  void ensureGridRows(uint32_t grid_row);
  void computeGridRow(uint32_t grid_row, std::vector<int32_t>* values);
  void generateRow(uint32_t y, uint8_t* out);
  /// row_fields_ and row_slopes_ for the row `fy` px below the cached top grid row.
  void interpolateRowFields(int32_t fy);
  const int32_t* rowField(Field f) const { return row_fields_.data() + size_t(f) * grid_cols_; }
  const int32_t* rowSlopes(Field f) const { return row_slopes_.data() + size_t(f) * grid_cols_; }
  RowFootprint rowFootprint(uint32_t y) const;
  /// elevation_[0..count] for pixels x0..x0 + count of row y (one past the chunk, for slopes).
  void chunkElevation(uint32_t y, uint32_t x0, uint32_t count);
  void addFineOctave(const Octave& octave, uint32_t y, uint32_t x0, uint32_t count);
  CellLines cellLines(uint32_t gx) const;
  CellBorders cellBorders(uint32_t cell_x, const RowFootprint& footprint) const;
  /// Writes the pixels [cell_x, cell_x + cell_count) of row y, within the chunk at x0.
  void colourCell(uint32_t y, uint32_t x0, uint32_t cell_x, uint32_t cell_count,
                  const RowFootprint& footprint, uint8_t* out) const;
  /// The colour of a valid pixel: sea, shaded land, or a line crossing it (pixel k of its
  /// cell). Returns a constant colour or `shaded` (3 bytes of scratch it may fill).
  const uint8_t* terrainColour(int32_t elevation, int32_t slope_x, int32_t slope_y, int32_t wet,
                               const CellLines& lines, uint32_t k, uint8_t* shaded) const;
  int32_t footprintNoise(uint32_t t, uint32_t side, uint32_t seed) const;
  uint32_t footprintDepth(uint32_t t, uint32_t side, uint32_t margin, uint32_t seed,
                          bool slant_up) const;

  SyntheticSpec spec_;
  uint32_t grid_cols_ = 0;                   // grid points per row, 16 px apart
  std::vector<Octave> coarse_[kFieldCount];  // octaves of 16 px and more, on the grid
  std::vector<Octave> fine_;                 // elevation octaves under 16 px, per pixel
  uint32_t footprint_seeds_[4] = {};         // left, right, top, bottom edges
  uint32_t margin_x_px_ = 0;                 // depth of the no-data border, left and right
  uint32_t margin_y_px_ = 0;                 // top and bottom
  // RGB by moisture level (dry to wet) and elevation step: kWetLevels x kPaletteSize x 3.
  std::vector<uint8_t> palettes_;
  // White noise for the fine octaves, indexed by lattice column plus a per-row hash.
  std::vector<int32_t> noise_table_;

  // Cached grid rows grid_row_ and grid_row_ + 1: per field, grid_cols_ values each.
  uint32_t grid_row_ = UINT32_MAX;
  std::vector<int32_t> grid_top_;
  std::vector<int32_t> grid_bottom_;
  // Per-row scratch, sized for one chunk of pixels.
  std::vector<int32_t> elevation_;   // kChunkPx + 1 values
  std::vector<int32_t> lattice_;     // one octave's lattice values along a row
  std::vector<int32_t> row_fields_;  // coarse fields interpolated to the current row
  std::vector<int32_t> row_slopes_;  // their change per 16 px down, per grid column
};

}  // namespace tessera::detail
