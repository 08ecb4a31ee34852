#pragma once
// The fast compositor's inner loop: one instance over one row of a tile, in chunks. It computes
// exactly what sampleInstance, the mask and blendTexel compute for each texel (the brute-force
// reference calls those), but only over the texels whose brush coordinates fall inside the
// image (solved per row in integers), with the taps gathered first and the arithmetic done in
// loops the compiler vectorises.

#include <cstdint>

#include "procedural/kernel.h"

namespace tessera::detail {

/// The level texels [first, last] of row `y` where the instance can draw (its brush
/// coordinates lie in [-1, w) x [-1, h) and within its reach); first > last when none.
struct RowSpan {
  int64_t first = 0;
  int64_t last = -1;
};
RowSpan instanceRowSpan(const InstanceSetup& setup, int64_t y);

/// Draws the instance over level texels [first, last] of row `y` into `row` (the canvas texels
/// of those level texels, RGBA, first at row[0]). `mask_values` (the layer's values of the
/// same texels) is null for unmasked brushes.
void drawInstanceRow(const InstanceSetup& setup, int64_t y, int64_t first, int64_t last,
                     const uint8_t* mask_values, uint8_t* row);

/// The alpha sampleInstance gives (tinted, with opacity, before any mask) for level texels
/// [first, last] of row `y`, which must lie inside instanceRowSpan(setup, y): for the analysis
/// phase's coverage, which needs no colour.
void instanceRowAlpha(const InstanceSetup& setup, int64_t y, int64_t first, int64_t last,
                      uint8_t* alpha);

}  // namespace tessera::detail
