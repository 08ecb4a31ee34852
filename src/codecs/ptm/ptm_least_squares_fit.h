#pragma once
// The encoder's fit of predictor 5's weights (ptm_least_squares.h) to one tile: the walk hands
// every coded texel's terms to LsFit, which gathers the normal equations per block position and
// channel, and solveLeastSquares rounds their solution to the payload's signed bytes.
// tessera::encoders only.

#include <cstdint>
#include <cstdlib>

#include "ptm/ptm_least_squares.h"

namespace tessera::detail {

/// Texels whose median residual exceeds 4 levels count in inverse proportion to it (Huber's
/// weights, from the median's residual so that one walk suffices): the edges' few large errors
/// would otherwise pull the weights away from the many small residuals.
constexpr int kLsRobustTarget = 16 * 4;

/// The nine terms of one channel (LsTexels at that channel), relative to 16 times the median.
inline void leastSquaresTerms(const LsTexels& t, int estimate16, int median, int* terms) {
  const int base = 16 * median;
  const uint8_t* texel = t.texel;
  const ptrdiff_t neighbours[4] = {t.left, t.up, t.up_left, t.up_right};
  for (uint32_t k = 0; k < 4; ++k) terms[k] = t.origin ? -base : 16 * texel[neighbours[k]] - base;
  terms[4] = 16 * *t.parent - base;
  terms[5] = 16 * *t.parent_side - base;
  terms[6] = 16 * *t.parent_near - base;
  terms[7] = 16 * *t.parent_diagonal - base;
  terms[8] = estimate16 - base;
}

/// The prediction from the terms themselves, which leastSquaresPredictFactored equals.
inline int leastSquaresPredict(const int8_t* weights, int median, const int* terms) {
  int sum = 0;
  for (uint32_t k = 0; k < kLsTerms; ++k) sum += weights[k] * terms[k];
  return std::clamp(median + ((sum + (1 << (kLsProductShift - 1))) >> kLsProductShift), 0, 255);
}

/// The weighted normal equations per position and channel. Terms stay below 2^15 in magnitude,
/// so doubles hold the sums of a 2048-px tile exactly enough.
struct LsFit {
  double gram[kLsSets][4][kLsTerms][kLsTerms] = {};  ///< the upper triangle, i <= j
  double moment[kLsSets][4][kLsTerms] = {};
  void add(uint32_t set, uint32_t channel, const int* terms, int target) {
    auto& gram_c = gram[set][channel];
    const double weight =
        std::abs(target) > kLsRobustTarget ? double(kLsRobustTarget) / std::abs(target) : 1.0;
    double t[kLsTerms];
    for (uint32_t i = 0; i < kLsTerms; ++i) t[i] = terms[i];
    for (uint32_t i = 0; i < kLsTerms; ++i) {
      for (uint32_t j = i; j < kLsTerms; ++j) gram_c[i][j] += weight * t[i] * t[j];
      moment[set][channel][i] += weight * t[i] * target;
    }
  }
};

/// Solves `fit` for each position and each of `channels` channels into `weights`,
/// [position][channel][term]. Without `with_estimate` the ninth term's weight is 0 and the
/// others are the least-squares fit of the eight.
void solveLeastSquares(const LsFit& fit, uint32_t channels, bool with_estimate, int8_t* weights);

}  // namespace tessera::detail
