#pragma once
// ptm's predictor 5 (docs/codecs.md, "ptm (6)"): the neighbour median plus a linear combination
// of nine terms whose weights the encoder fits to each tile by least squares (as GLICBAWLS does
// per texel, but once per tile) and sends in the payload. The terms are departures from the
// median in sixteenths of a level: the left, up, up-left and up-right texels, the four parent
// texels bilinear upsampling weighs, and predictor 4's estimate. The median follows the edges
// the neighbours show; the parent knows where the block's mean lies; the fit takes as much of
// each as the tile rewards. Terms relative to the median keep the rounded weights cheap. The
// weights are signed bytes in 1/128 units, per block position (0-3; a derived texel's guess at
// eq. 3's remainder takes position 3's) and channel. The fit is ptm_least_squares_fit.h's.

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace tessera::detail {

constexpr uint32_t kLsTerms = 9;
constexpr uint32_t kLsSets = 4;
/// A term is in 1/16 units and a weight in 1/128: their products are in 1/2048.
constexpr int kLsProductShift = 11;

constexpr size_t lsWeightBytes(uint32_t channels) {
  return size_t(kLsSets) * channels * kLsTerms;
}

/// The texels a prediction reads: the left, up, up-left and up-right neighbours as offsets from
/// `texel` (unused at the tile's first texel, `origin`), and the block's parent texel P and the
/// parent texels beside it horizontally, vertically and diagonally.
struct LsTexels {
  const uint8_t* texel;
  ptrdiff_t left, up, up_left, up_right;
  bool origin;
  const uint8_t *parent, *parent_side, *parent_near, *parent_diagonal;
};

/// The prediction with the median factored out of the sum: sum_k w_k (v_k - 16 m) =
/// sum_k w_k v_k - 16 m sum_k w_k, the same integer with fewer operations waiting on the left
/// texel. `weight_sum` is the sum of the nine `weights`, `estimate16` predictor 4's estimate.
inline int leastSquaresPredictFactored(const int8_t* weights, int weight_sum, const LsTexels& t,
                                       int estimate16, int median) {
  const uint8_t* texel = t.texel;
  // At the tile's first texel the neighbour terms are -16 m with m = 0: nothing.
  const int neighbours = t.origin
                             ? 0
                             : weights[0] * texel[t.left] + weights[1] * texel[t.up] +
                                   weights[2] * texel[t.up_left] + weights[3] * texel[t.up_right];
  const int parents = weights[4] * *t.parent + weights[5] * *t.parent_side +
                      weights[6] * *t.parent_near + weights[7] * *t.parent_diagonal;
  const int sum = 16 * (neighbours + parents) + weights[8] * estimate16 - 16 * median * weight_sum;
  return std::clamp(median + ((sum + (1 << (kLsProductShift - 1))) >> kLsProductShift), 0, 255);
}

/// Whether any of `weights` ([position][channel][term]) gives predictor 4's estimate, the ninth
/// term, a weight. Without one the decoders skip all of predictor 4's work.
inline bool usesEstimate(const int8_t* weights, uint32_t channels) {
  for (size_t i = kLsTerms - 1; i < lsWeightBytes(channels); i += kLsTerms)
    if (weights[i] != 0) return true;
  return false;
}

/// Each position's and channel's weight sum, for leastSquaresPredictFactored.
inline void sumLeastSquaresWeights(const int8_t* weights, uint32_t channels,
                                   int (&sums)[kLsSets][4]) {
  for (uint32_t set = 0; set < kLsSets; ++set)
    for (uint32_t c = 0; c < 4; ++c) {
      sums[set][c] = 0;
      for (uint32_t k = 0; c < channels && k < kLsTerms; ++k)
        sums[set][c] += weights[(set * channels + c) * kLsTerms + k];
    }
}

}  // namespace tessera::detail
