#pragma once
// ptm's predictor 5 (least squares; docs/codecs.md, "ptm (6)"): its terms, its prediction from
// the payload's weights, and the encoder's fit of those weights. The texel walk that uses them
// is ptm_walk.h's.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

namespace tessera::detail {

// Predictor 5: a linear prediction whose weights the encoder fits to each tile. Its terms are
// departures from the neighbour median in sixteenths of a level: the left, up, up-left and
// up-right texels, the four parent texels that bilinear upsampling weighs, and predictor 4's
// prediction (in sixteenths, the block's pull included; for a derived texel without it). The
// median alone predicts well where the texture follows edges the neighbours show; the parent
// knows where the block's mean lies, which the median cannot see, and how much to trust each
// depends on the image, so the fit decides (as in the least-squares predictors of lossless
// coders such as Meyer & Tischer's GLICBAWLS, but once per tile, not per texel). The weights
// are signed bytes in 1/128 units, per block position (0-3; a derived texel's guess at eq. 3's
// remainder uses position 3's) and channel. On the codec study's photograph the default's
// pyramid came out 20 % smaller with it (docs/benchmarks.md). Terms relative to the median keep
// the weights' rounding cheap; absolute texel values, where a rounded weight errs by its share
// of the whole level, gave up most of the gain.
constexpr uint32_t kLsTerms = 9;
constexpr uint32_t kLsSets = 4;
constexpr int kLsWeightScale = 128;
// A term is in 1/16 units and a weight in 1/128 ones: their products in 1/2048.
constexpr int kLsProductShift = 11;

constexpr size_t lsWeightBytes(uint32_t channels) {
  return size_t(kLsSets) * channels * kLsTerms;
}

// Texels whose median residual exceeds 4 levels count in the fit in inverse proportion to it
// (Huber's weights, from the median's residual rather than the fit's own so that one walk
// suffices). Plain least squares let the edges' large errors pull the weights away from what
// codes the many small residuals best: with these weights the study's photograph coded 4 %
// smaller (15.9:1 against 15.3:1 with predictor 5 alone) and the map 2 %; 2, 8 and 16 levels,
// weights 1 / (|r| + k) and a second walk weighted by the fit's own residuals were no better
// on the three inputs together.
constexpr int kLsRobustTarget = 16 * 4;

// The normal equations of predictor 5's fit per position and channel, weighted. The weights
// travel in the payload, so the fit need not be reproducible anywhere but in the encoder that
// ran it; terms stay below 2^15 in magnitude, so doubles hold the sums of a 2048-px tile with
// room to spare.
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

// Predictor 5's terms for one channel of the texel at `texel` (neighbour offsets as the walk
// sets them; all zero at the tile's first texel, which has no neighbours), relative to the
// neighbour median `median`. `estimate16` is predictor 4's estimate in sixteenths.
inline void leastSquaresTerms(const uint8_t* texel, ptrdiff_t left, ptrdiff_t up, ptrdiff_t up_left,
                              ptrdiff_t up_right, bool origin, const uint8_t* parent,
                              const uint8_t* parent_side, const uint8_t* parent_near,
                              const uint8_t* parent_diagonal, int estimate16, int median,
                              int* terms) {
  const int base = 16 * median;
  if (origin) {
    for (uint32_t k = 0; k < 4; ++k) terms[k] = -base;
  } else {
    terms[0] = 16 * texel[left] - base;
    terms[1] = 16 * texel[up] - base;
    terms[2] = 16 * texel[up_left] - base;
    terms[3] = 16 * texel[up_right] - base;
  }
  terms[4] = 16 * *parent - base;
  terms[5] = 16 * *parent_side - base;
  terms[6] = 16 * *parent_near - base;
  terms[7] = 16 * *parent_diagonal - base;
  terms[8] = estimate16 - base;
}

inline int leastSquaresPredict(const int8_t* weights, int median, const int* terms) {
  int sum = 0;
  for (uint32_t k = 0; k < kLsTerms; ++k) sum += weights[k] * terms[k];
  return std::clamp(median + ((sum + (1 << (kLsProductShift - 1))) >> kLsProductShift), 0, 255);
}

// leastSquaresPredict of leastSquaresTerms' terms, without the terms: the median factored out
// of the sum, sum_k w_k (v_k - 16 m) = sum_k w_k v_k - 16 m sum_k w_k, which is the same
// integer (no term can overflow) with fewer operations waiting on the left texel and the
// median. `weight_sum` is the sum of the nine `weights`. Arguments as leastSquaresTerms'.
inline int leastSquaresPredictFactored(const int8_t* weights, int weight_sum, const uint8_t* texel,
                                       ptrdiff_t left, ptrdiff_t up, ptrdiff_t up_left,
                                       ptrdiff_t up_right, bool origin, const uint8_t* parent,
                                       const uint8_t* parent_side, const uint8_t* parent_near,
                                       const uint8_t* parent_diagonal, int estimate16, int median) {
  // At the tile's first texel the neighbour terms are -16 m with m = 0: nothing.
  const int neighbours = origin ? 0
                                : weights[0] * texel[left] + weights[1] * texel[up] +
                                      weights[2] * texel[up_left] + weights[3] * texel[up_right];
  const int parents = weights[4] * *parent + weights[5] * *parent_side + weights[6] * *parent_near +
                      weights[7] * *parent_diagonal;
  const int sum = 16 * (neighbours + parents) + weights[8] * estimate16 - 16 * median * weight_sum;
  return std::clamp(median + ((sum + (1 << (kLsProductShift - 1))) >> kLsProductShift), 0, 255);
}

/// Whether any of `weights` ([position][channel][term], `channels` channels) gives predictor 4's
/// estimate, the ninth term, a weight. Without one, predictor 5 needs nothing of predictor 4's
/// (the upsampled parent, the departures, the block's pull), and the decoders skip it.
inline bool usesEstimate(const int8_t* weights, uint32_t channels) {
  for (size_t i = kLsTerms - 1; i < lsWeightBytes(channels); i += kLsTerms)
    if (weights[i] != 0) return true;
  return false;
}

/// Solves `fit`'s normal equations for each position and each of `channels` channels into
/// `weights`, [position][channel][term], the payload's layout. Without `with_estimate`, the
/// fit leaves out predictor 4's estimate, whose weight is then 0 (usesEstimate).
void solveLeastSquares(const LsFit& fit, uint32_t channels, bool with_estimate, int8_t* weights);

}  // namespace tessera::detail
